//! `holo display check FILE`: which shipped CNNs serve a display profile, how (σ, the laser spread's mapping
//! ceiling and estimated cost, the volume), or why not and what would serve; and the advice every command
//! prints when a display is refused ([`serving_hint`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use tensorholo::display::{
    DisplayMapping, DisplayProfile, DisplayRefusal, VolumeFit, RETRAIN_COST,
};
use tensorholo::model::embedded::{check_display, ShippedModelCheck, PREFILTER_OFFSETS_MM};
use tensorholo::optics::OpticalSetup;
use tensorholo::HoloError;

/// Arguments of `holo display`.
#[derive(Debug, Args)]
pub struct DisplayArgs {
    #[command(subcommand)]
    command: DisplayCommand,
}

#[derive(Debug, Subcommand)]
enum DisplayCommand {
    /// Which shipped CNNs serve a display profile (docs/DISPLAYS.md): for each offset of the profile, each
    /// hologram CNN (8/15/30 layers and the LDI CNN, f32 and int8) and the pre-filter each pairs with. For each:
    /// σ, the mapping's ceiling and estimated cost (against the model's test-split score), or why it does not
    /// serve and what would. Exit status 0 when every hologram CNN serves the display at every offset, 1 when
    /// one does not, 2 for a bad profile.
    Check(CheckArgs),
}

/// Arguments of `holo display check`.
#[derive(Debug, Args)]
struct CheckArgs {
    /// The display profile (JSON, docs/DISPLAYS.md).
    file: PathBuf,
    /// Largest spread of the lasers' depth scales (a fraction: 0.01 = 1 %); default: the serving rule's for
    /// each model (an estimated cost within 0.3 dB of its model-card score).
    #[arg(long)]
    wavelength_ratio_tolerance: Option<f64>,
    /// Print the checks as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `holo display`; returns whether the display is served (the exit status).
pub fn run(args: &DisplayArgs) -> Result<bool> {
    match &args.command {
        DisplayCommand::Check(a) => check(a),
    }
}

fn check(args: &CheckArgs) -> Result<bool> {
    let profile = DisplayProfile::from_path(&args.file)
        .map_err(|e| crate::output::UsageError(format!("{e}")))?;
    let checks = check_display(
        &profile.optics(),
        &profile.offsets_m,
        args.wavelength_ratio_tolerance,
    )
    .with_context(|| format!("checking {}", args.file.display()))?;
    let served = checks
        .iter()
        .filter(|c| c.kind == "hologram-cnn")
        .all(ShippedModelCheck::served);
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "profile": crate::output::path_text(&args.file),
                "served": served,
                "checks": checks,
            }))?
        );
        return Ok(served);
    }
    let name = profile
        .name
        .clone()
        .unwrap_or_else(|| crate::output::path_text(&args.file));
    let w = profile.wavelengths_m;
    println!(
        "{name}: {} µm, lasers {:.1}/{:.1}/{:.1} nm, volume {} mm, offsets {} mm",
        profile.pixel_pitch_m * 1e6,
        w[0] * 1e9,
        w[1] * 1e9,
        w[2] * 1e9,
        mm(profile.volume_depth_m),
        profile
            .offsets_m
            .iter()
            .map(|&s| format!("{}", mm(s)))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!();
    println!("| offset (mm) | model | precision | served | σ | spread | ceiling (dB) | est. cost (dB) | volume | why not |");
    println!("|---:|---|---|---|---:|---:|---:|---:|---|---|");
    for c in &checks {
        let model = if c.file.is_empty() {
            format!("pre-filter for holo{}", c.layers)
        } else {
            c.file.clone()
        };
        let row = match (&c.mapping, &c.refusal, &c.note) {
            (Some(m), _, _) => format!(
                "yes | {:.6} | {:.2} % | {} | {:.2} | {} | ",
                m.scale,
                m.spread() * 100.0,
                if m.ceiling_db.is_finite() {
                    format!("{:.1}", m.ceiling_db)
                } else {
                    "∞".into()
                },
                m.cost_db,
                volume(m.volume, m.served_volume_depth_m())
            ),
            (None, Some(r), _) => {
                format!("no | | | | | | {}", r.key.trim_start_matches("tensorholo."))
            }
            (None, None, Some(note)) => format!("– | | | | | | {note}"),
            (None, None, None) => "? | | | | | | ".into(),
        };
        println!("| {} | {model} | {} | {row} |", mm(c.offset_m), c.precision);
    }
    // Why not, once per distinct refusal, with what would serve.
    let mut seen = Vec::new();
    let optics = profile.optics();
    for (c, r) in checks
        .iter()
        .filter_map(|c| c.refusal.as_ref().map(|r| (c, r)))
    {
        // One block per cause and remedy (the models of each depth refuse alike).
        let key = (r.key.clone(), format!("{:?} {:?}", r.nearest, r.tolerance));
        if seen.contains(&key) {
            continue;
        }
        seen.push(key);
        println!();
        println!("Not served: {r}");
        let asked = Requested {
            optics: &optics,
            offset_m: c.offset_m,
            tolerance: args.wavelength_ratio_tolerance,
            profile: Some((&args.file, &profile)),
        };
        println!("{}", serving_hint(r, &asked));
    }
    println!();
    println!(
        "{}",
        if served {
            "served: every shipped hologram CNN serves this display at every offset (exit 0)"
        } else {
            "not served by every shipped hologram CNN (exit 1)"
        }
    );
    Ok(served)
}

/// A volume fit in a table cell.
fn volume(fit: VolumeFit, served_m: f64) -> String {
    match fit {
        VolumeFit::Mapped => format!("{} mm", mm(served_m)),
        VolumeFit::Rounded { requested_m } => {
            format!("{} mm → {} mm", mm(requested_m), mm(served_m))
        }
        VolumeFit::Partial { fraction } => {
            format!("{:.1} % of {} mm", fraction * 100.0, mm(served_m))
        }
        VolumeFit::TooDeep => "too deep".into(),
    }
}

/// Metres as millimetres to the nanometre, without the float noise of the conversion (1.3113375, not
/// 1.3113375000000003).
fn mm(metres: f64) -> f64 {
    (metres * 1e12).round() / 1e9
}

/// What a refused display was asked for: its optics, the SLM offset and laser tolerance in force, and the
/// `--display` file where one was given.
pub struct Requested<'a> {
    /// The display's optics (metres).
    pub optics: &'a OpticalSetup,
    /// The SLM offset asked for, metres (`--offset-mm` or the profile's).
    pub offset_m: f64,
    /// `--wavelength-ratio-tolerance`, `None` for the serving rule's.
    pub tolerance: Option<f64>,
    /// The `--display` file and its profile.
    pub profile: Option<(&'a Path, &'a DisplayProfile)>,
}

/// The offsets (metres) at which a shipped pre-filter serves `optics`, with the pre-filter's offset on the
/// training display (mm): `σ·s` for `s` = 6 and 12 mm, where the hologram CNNs' mapping holds there (the
/// non-paraxial residual grows with the offset, so a display may be served at one and not the other).
fn prefilter_offsets(optics: &OpticalSetup, tolerance: Option<f64>) -> Vec<(f64, u32)> {
    let trained = OpticalSetup::default();
    let Ok(at_zero) = DisplayMapping::compute(&trained, optics, 0.0, tolerance, 0.0) else {
        return Vec::new();
    };
    PREFILTER_OFFSETS_MM
        .iter()
        .map(|&mm| (at_zero.scale * mm as f64 * 1e-3, mm))
        .filter(|&(s, _)| {
            DisplayMapping::compute(&trained, optics, s, tolerance, 0.0)
                .is_ok_and(|m| m.refusal("the shipped CNNs").is_none())
        })
        .collect()
}

/// What would serve a refused display, in the order to try, for the `--display` file where one was given:
/// an offset a shipped pre-filter serves (where the offset is at fault), the nearest display the model
/// serves (as a profile to save), the laser tolerance with its estimated cost, retraining with its cost.
pub fn serving_hint(r: &DisplayRefusal, asked: &Requested) -> String {
    let profile = asked.profile;
    let mut out = "What would serve this display:".to_string();
    let mut n = 0;
    let mut step = |text: String| {
        n += 1;
        out.push_str(&format!("\n{n}. {text}"));
    };
    // An offset too far for the paraxial mapping (the pitch's residual) or one no model was trained for:
    // the offsets the shipped pre-filters serve on this display, in the display's millimetres.
    let offset_at_fault = r.key.ends_with("pixel_pitch_m") || r.key.ends_with("offset_m");
    let served = prefilter_offsets(asked.optics, asked.tolerance);
    if offset_at_fault && asked.offset_m != 0.0 && !served.is_empty() {
        let list = served
            .iter()
            .map(|&(s, trained)| format!("--offset-mm {} (the {trained} mm pre-filter)", mm(s)))
            .collect::<Vec<_>>()
            .join(" or ");
        // A profile offset given in metres where --offset-mm wants millimetres reads 1000× too small.
        let units = profile
            .and_then(|(_, p)| {
                p.offsets_m
                    .iter()
                    .find(|&&o| o != 0.0 && (asked.offset_m * 1e3 - o).abs() <= 1e-9 * o.abs())
            })
            .map_or(String::new(), |o| {
                format!(
                    " (--offset-mm is in millimetres: the profile's offsets_m {o} m is --offset-mm {})",
                    mm(*o)
                )
            });
        step(format!(
            "an offset the shipped pre-filters serve on this display: {list}, not {} mm{units}",
            mm(asked.offset_m)
        ));
    }
    if let Some(n) = r.nearest {
        let (o, s) = (n.optics(), n.offset_m);
        match profile {
            Some((path, p)) => step(format!(
                "the nearest display this model serves, as a profile to save beside {}:\n{}",
                path.display(),
                p.with_display(&n).to_json().trim_end()
            )),
            None => step(format!(
                "the nearest display this model serves: --pitch-m {} --wavelengths-m {},{},{} \
                 --volume-depth-m {} --offset-mm {}",
                o.pixel_pitch_m,
                o.wavelengths_m[0],
                o.wavelengths_m[1],
                o.wavelengths_m[2],
                o.volume_depth_m,
                s * 1e3
            )),
        }
    }
    if let Some((t, cost)) = r.tolerance {
        step(format!(
            "--wavelength-ratio-tolerance {t} serves this display as it is, at an estimated cost of {cost:.2} dB \
             (wavelength_ratio_tolerance in the SDK and the bindings)"
        ));
    }
    let file = profile.map_or_else(
        || "PROFILE.json".to_string(),
        |(p, _)| crate::output::path_text(p),
    );
    step(format!(
        "retrain for it: `training/retrain.sh --display {file} --out retrain/display` ({RETRAIN_COST}; \
         docs/DISPLAYS.md, \"Retraining for another display\")"
    ));
    out
}

/// `e` with `what` as its context; where it is a display refusal, first prints what would serve the display
/// ([`serving_hint`]) to stderr and says so in the context.
pub fn with_serving_hint(e: HoloError, what: &str, asked: &Requested) -> anyhow::Error {
    match &e {
        HoloError::DisplayNotServed(r) => {
            eprintln!("{}\n", serving_hint(r, asked));
            anyhow::Error::new(e).context(format!(
                "{what}: the model does not serve this display as it is (what would serve it is above)"
            ))
        }
        _ => anyhow::Error::new(e).context(what.to_string()),
    }
}
