//! The foveation flags `holo render` and `holo video` share ([`FoveaArgs`]: the gaze, its depth, the fovea's
//! size) and how they become the SDK's [`FoveationOptions`] and [`Gaze`] (docs/FOVEATION.md).

use anyhow::{bail, Context, Result};
use clap::Args;
use tensorholo::display::DEFAULT_EYEPIECE_FOCAL_M;
use tensorholo::foveation::{FoveaRadius, FoveationOptions, Gaze, DEFAULT_BAND_PX};

/// Foveated frames: the hologram CNN only where the viewer looks (docs/FOVEATION.md).
#[derive(Debug, Args)]
pub struct FoveaArgs {
    /// Foveate every frame on this gaze point X,Y: output pixels after --size, (0, 0) the top-left pixel's
    /// centre, x right, y down. The hologram CNN runs on a tile around it (the fovea, a blend band and the
    /// CNN's receptive radius); elsewhere the frame is a 2D hologram with synthetic blur, in focus at the
    /// gaze's depth. Default fovea: 5° behind the paper's 21 mm eyepiece.
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true)]
    pub gaze: Option<String>,
    /// `holo video`: a moving gaze, one CSV row per frame: `frame,x,y[,depth]` (`frame` the 0-based index of
    /// the frame in the sequence; x, y as --gaze; depth in metres as --gaze-depth, or empty), a header row
    /// allowed; every frame once.
    #[arg(long, value_name = "FILE.csv", conflicts_with_all = ["gaze", "gaze_depth"])]
    pub gaze_track: Option<std::path::PathBuf>,
    /// The depth the viewer focuses at, metres from the midpoint plane in hologram space (positive towards
    /// the viewer, as the focal planes: the volume's near end at +volume/2). Default: the scene's depth at the
    /// gaze point (the median of a 17×17 window).
    #[arg(
        long,
        value_name = "METRES",
        allow_hyphen_values = true,
        requires = "gaze"
    )]
    pub gaze_depth: Option<f64>,
    /// The fovea's radius in degrees of visual angle behind the eyepiece (--eyepiece-mm, default 21 mm):
    /// R_px = f·tan(R)/pitch. Default 5.
    #[arg(
        long,
        value_name = "DEGREES",
        requires = "gaze",
        conflicts_with = "fovea_px"
    )]
    pub fovea_deg: Option<f64>,
    /// The fovea's radius in SLM pixels (instead of --fovea-deg).
    #[arg(
        long,
        value_name = "PIXELS",
        allow_hyphen_values = true,
        requires = "gaze"
    )]
    pub fovea_px: Option<f64>,
    /// Width in pixels of the blend band outside the fovea (from R to R + band): the CNN's field fades
    /// linearly into the periphery's there.
    #[arg(long, value_name = "PIXELS", allow_hyphen_values = true, default_value_t = DEFAULT_BAND_PX)]
    pub fovea_band_px: f64,
}

impl FoveaArgs {
    /// The foveation options of the flags (`None` without --gaze); `eyepiece_mm` is --eyepiece-mm.
    /// Errors: name the flag of a value the SDK refuses (a negative or non-finite radius, a band under 1).
    pub fn options(&self, eyepiece_mm: Option<f64>) -> Result<Option<FoveationOptions>> {
        if self.gaze.is_none() && self.gaze_track.is_none() {
            let given = [
                ("--gaze-depth", self.gaze_depth.is_some()),
                ("--fovea-deg", self.fovea_deg.is_some()),
                ("--fovea-px", self.fovea_px.is_some()),
                ("--fovea-band-px", self.fovea_band_px != DEFAULT_BAND_PX),
            ];
            if let Some((flag, _)) = given.iter().find(|(_, g)| *g) {
                bail!("{flag} foveates frames: give the gaze too (--gaze X,Y, or --gaze-track FILE.csv in holo video)");
            }
            return Ok(None);
        }
        let radius = match (self.fovea_px, self.fovea_deg) {
            (Some(pixels), _) => FoveaRadius::Pixels { pixels },
            (None, degrees) => FoveaRadius::Degrees {
                degrees: degrees.unwrap_or(5.0),
                eyepiece_focal_m: eyepiece_mm.map_or(DEFAULT_EYEPIECE_FOCAL_M, |mm| mm * 1e-3),
            },
        };
        let options = FoveationOptions {
            radius,
            band_px: self.fovea_band_px,
            ..FoveationOptions::default()
        };
        // The SDK's checks, at the flags (the pitch only scales a valid radius).
        if let Err(e) = options.check() {
            let flag = match (&e, self.fovea_px.is_some()) {
                (
                    tensorholo::HoloError::InvalidParameter {
                        name: "band_px", ..
                    },
                    _,
                ) => "--fovea-band-px",
                (
                    tensorholo::HoloError::InvalidParameter {
                        name: "eyepiece_focal_m",
                        ..
                    },
                    _,
                ) => "--eyepiece-mm",
                (_, true) => "--fovea-px",
                (_, false) => "--fovea-deg",
            };
            return Err(anyhow::Error::new(e).context(flag));
        }
        Ok(Some(options))
    }

    /// The gaze of --gaze and --gaze-depth (`None` without --gaze). Errors: a value that is not `X,Y` with two
    /// finite numbers, a non-finite --gaze-depth (the frame's bounds are checked by the SDK, per frame).
    pub fn gaze(&self) -> Result<Option<Gaze>> {
        let Some(text) = &self.gaze else {
            return Ok(None);
        };
        let (x, y) = parse_point(text).with_context(|| format!("--gaze {text}"))?;
        if let Some(d) = self.gaze_depth {
            if !d.is_finite() {
                bail!("--gaze-depth {d}: must be a finite distance in metres");
            }
        }
        Ok(Some(Gaze {
            x,
            y,
            depth_m: self.gaze_depth,
        }))
    }
}

/// `X,Y` as two finite numbers. Errors: anything else, saying what is expected.
pub fn parse_point(text: &str) -> Result<(f64, f64)> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y] = parts.as_slice() else {
        bail!("expected X,Y (two numbers, pixels), e.g. --gaze 960,540");
    };
    let number = |s: &str, what: &str| -> Result<f64> {
        let v: f64 = s
            .parse()
            .with_context(|| format!("{what} {s:?} is not a number"))?;
        if !v.is_finite() {
            bail!("{what} {s:?} is not finite");
        }
        Ok(v)
    };
    Ok((number(x, "X")?, number(y, "Y")?))
}

/// The full 3D frame of a foveated `holo render --evaluate`: what the same session renders without a gaze,
/// kept to score the foveated frame against, bin by bin.
pub struct FullFrame {
    /// The CNN's midpoint hologram `[3, H, W]`.
    pub midpoint: ndarray::Array3<num_complex::Complex32>,
    /// What the SLM displays, as the post-encoding midpoint hologram `[3, H, W]` (Eq. 8–10).
    pub displayed: ndarray::Array3<num_complex::Complex32>,
}

/// The normalised depths of the eccentricity bins' focal planes.
const BIN_DEPTHS: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];

/// `--evaluate`'s scores of a foveated frame by eccentricity: for the bins `0–R`, `R–2R`, `2R–4R` and beyond
/// (pixels from the gaze), per focal plane of [`BIN_DEPTHS`], the PSNR of the foveated frame's focal stack
/// (its midpoint hologram and what its SLM codes display) against the full 3D frame's and against SM-LBM's
/// (`truth`), and the full frame's against SM-LBM's for comparison. Each score puts the test at its
/// least-squares scale in the bin (the normalisers differ) and takes the reference's largest value on the
/// plane as the peak.
///
/// Errors: the reconstructions' ([`tensorholo::optics::focal_stack`]).
pub fn eccentricity_bins(
    report: &tensorholo::foveation::FoveaReport,
    foveated: [&ndarray::Array3<num_complex::Complex32>; 2],
    full: &FullFrame,
    truth: &ndarray::Array3<num_complex::Complex32>,
    setup: &tensorholo::optics::OpticalSetup,
    options: tensorholo::optics::PropagationOptions,
) -> Result<serde_json::Value> {
    let (_, h, w) = truth.dim();
    let r = report.radius_px.max(1.0);
    let edges = [0.0, r, 2.0 * r, 4.0 * r, f64::INFINITY];
    let stack = |f: &ndarray::Array3<num_complex::Complex32>| {
        tensorholo::optics::focal_stack(f.view(), setup, 0.0, &BIN_DEPTHS, options, false)
    };
    let truth = stack(truth)?;
    let full_mid = stack(&full.midpoint)?;
    let full_shown = stack(&full.displayed)?;
    let fov_mid = stack(foveated[0])?;
    let fov_shown = stack(foveated[1])?;
    let bin_of = |y: usize, x: usize| {
        let d = (x as f64 - report.gaze.x).hypot(y as f64 - report.gaze.y);
        edges.windows(2).position(|e| d >= e[0] && d < e[1])
    };
    let bins: Vec<usize> = (0..h * w)
        .map(|i| bin_of(i / w, i % w).unwrap_or(edges.len() - 2))
        .collect();
    let scores = |reference: &[ndarray::Array3<f32>], test: &[ndarray::Array3<f32>]| {
        reference
            .iter()
            .zip(test)
            .map(|(r, t)| binned_psnr(r, t, &bins, edges.len() - 1))
            .collect::<Vec<_>>()
    };
    Ok(serde_json::json!({
        "bins_px": edges.windows(2).map(|e| [e[0], e[1]]).collect::<Vec<_>>(),
        "focal_depths": BIN_DEPTHS,
        "against_full": {
            "midpoint": scores(&full_mid, &fov_mid),
            "displayed": scores(&full_shown, &fov_shown),
        },
        "against_sm_lbm": {
            "foveated_midpoint": scores(&truth, &fov_mid),
            "foveated_displayed": scores(&truth, &fov_shown),
            "full_midpoint": scores(&truth, &full_mid),
            "full_displayed": scores(&truth, &full_shown),
        },
    }))
}

/// PSNR (dB) of `test` against `reference` (`[3, H, W]`) in each of `n` bins (`bins`: a bin per pixel), the
/// test at its least-squares scale in the bin, the peak the reference's largest value; `null` for an empty
/// bin.
fn binned_psnr(
    reference: &ndarray::Array3<f32>,
    test: &ndarray::Array3<f32>,
    bins: &[usize],
    n: usize,
) -> Vec<Option<f64>> {
    let peak = f64::from(reference.iter().copied().fold(0.0f32, f32::max));
    let (mut rt, mut tt, mut rr, mut count) = (
        vec![0.0f64; n],
        vec![0.0f64; n],
        vec![0.0f64; n],
        vec![0usize; n],
    );
    let hw = bins.len();
    for (c, (r, t)) in reference.iter().zip(test.iter()).enumerate() {
        let b = bins[c % hw];
        let (r, t) = (f64::from(*r), f64::from(*t));
        rt[b] += r * t;
        tt[b] += t * t;
        rr[b] += r * r;
        count[b] += 1;
    }
    (0..n)
        .map(|b| {
            (count[b] > 0).then(|| {
                let s = if tt[b] > 0.0 { rt[b] / tt[b] } else { 0.0 };
                // Σ(r − s·t)² = Σr² − 2sΣrt + s²Σt².
                let se = (rr[b] - 2.0 * s * rt[b] + s * s * tt[b]).max(1e-30);
                10.0 * (peak * peak * count[b] as f64 / se).log10()
            })
        })
        .collect()
}

/// The gazes of `--gaze-track FILE.csv` for a sequence of `frames` frames, in frame order: rows
/// `frame,x,y[,depth]` (a header row allowed, blank lines skipped).
///
/// Errors: name the file and the line: a row that is not 3 or 4 fields of numbers (a frame index, finite x
/// and y, a finite depth or nothing), a frame listed twice, a frame beyond the sequence; and a frame of the
/// sequence the file leaves out.
pub fn read_gaze_track(path: &std::path::Path, frames: usize) -> Result<Vec<Gaze>> {
    let text = tensorholo::io::read_text(path)
        .with_context(|| format!("--gaze-track {}", path.display()))?;
    let mut gazes: Vec<Option<Gaze>> = vec![None; frames];
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let at = || format!("--gaze-track {}, line {}", path.display(), n + 1);
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if n == 0 && fields.first().is_some_and(|f| f.parse::<f64>().is_err()) {
            continue; // the header
        }
        if !(3..=4).contains(&fields.len()) {
            bail!("{}: expected frame,x,y[,depth], got {line:?}", at());
        }
        let frame: usize = fields[0].parse().with_context(|| {
            format!("{}: the frame {:?} is not a 0-based index", at(), fields[0])
        })?;
        let (x, y) = parse_point(&format!("{},{}", fields[1], fields[2])).with_context(at)?;
        let depth_m = match fields.get(3).filter(|d| !d.is_empty()) {
            Some(d) => {
                let v: f64 = d
                    .parse()
                    .with_context(|| format!("{}: the depth {d:?} is not a number", at()))?;
                if !v.is_finite() {
                    bail!("{}: the depth {d:?} is not finite", at());
                }
                Some(v)
            }
            None => None,
        };
        let Some(slot) = gazes.get_mut(frame) else {
            bail!(
                "{}: frame {frame}, but the sequence has {frames} frames (0 to {})",
                at(),
                frames.saturating_sub(1)
            );
        };
        if slot.is_some() {
            bail!("{}: frame {frame} is listed twice", at());
        }
        *slot = Some(Gaze { x, y, depth_m });
    }
    gazes
        .into_iter()
        .enumerate()
        .map(|(i, g)| {
            g.with_context(|| format!("--gaze-track {}: no row for frame {i}", path.display()))
        })
        .collect()
}
