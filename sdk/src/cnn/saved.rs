//! [`SavedPlans`]: what a session's CNN plans were made of, as a JSON file the caller owns (format
//! `tensorholo.cnn-plans`, version 2; version 1 files, whose rows say `any` for `auto`, still read): per session (network and resolution) the engine, tract's layout and the
//! threads, and per f32 layer shape the kernel row it ran. A tuning ([`crate::cnn::PlanSource::Tune`]) writes
//! one; a later session given it ([`crate::cnn::PlanSource::Saved`]) makes the same plans without timing
//! anything, so every run with the file gives the same bits.
//!
//! ```json
//! {
//!   "format": "tensorholo.cnn-plans",
//!   "version": 2,
//!   "isa": "avx512vnni",
//!   "origin": "tuned by tensorholo 0.1.0 on 2 threads",
//!   "sessions": [{ "network": "hologram-cnn-8-f32-in4", "resolution": [384, 384],
//!                  "engine": "native", "layout": "channels-first", "threads": 2 }],
//!   "rows": [{ "c_in": 24, "c_out": 24, "algorithms": "auto", "row": "conv3x3.f32.wino4x4.24x1.avx512" }]
//! }
//! ```
//!
//! The rows are for one kernel ISA level (`isa`, `tensorholo_kernels::Isa::name`): a file made on another
//! level is refused when a session uses it. Imports only `options` of `cnn/`.

use std::collections::BTreeSet;

use tensorholo_kernels::{registry, Isa};

use super::options::{CnnEngine, CnnLayout, ConvAlgorithm, MAX_CNN_THREADS};
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, Result};

/// The `format` of a saved-plans file.
pub const SAVED_PLANS_FORMAT: &str = "tensorholo.cnn-plans";
/// The `version` this build writes; it reads it and version 1 (whose rows say `any` where version 2 says
/// `auto`: one algorithm enum, [`ConvAlgorithm`], since version 2).
pub const SAVED_PLANS_VERSION: u32 = 2;
/// The most input or output channels a saved row may name (far above any TensorHolo layer's 24).
const MAX_CHANNELS: usize = 4096;
/// The most entries of either list: far above the layer shapes and sizes one app uses.
const MAX_ENTRIES: usize = 4096;

/// One f32 layer shape's kernel row: a `c_in → c_out` 3×3 convolution chosen among `algorithms` runs the row
/// named `row` (`tensorholo_kernels::registry`, e.g. `conv3x3.f32.wino4x4.24x1.avx512`).
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedRow {
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    /// What the row was chosen among: [`ConvAlgorithm::Auto`] for every algorithm (`any` in version 1
    /// files), or the one pinned (direct alone for an int8 file's f32 first and last layers).
    pub algorithms: ConvAlgorithm,
    /// The kernel row's name.
    pub row: String,
}

/// One session's engine, layout and threads: the hologram CNN `network` (`network_key`) at `resolution`
/// `[height, width]` pixels (its pre-filter runs on the same engine and threads).
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedSession {
    /// The hologram CNN, as `network_key` names it (e.g. `hologram-cnn-8-f32-in4`).
    pub network: String,
    /// `[height, width]` in pixels.
    pub resolution: [usize; 2],
    /// The engine that ran (never `auto`).
    pub engine: CnnEngine,
    /// tract's layout (`channels-first` for the native engine; never `auto`).
    pub layout: CnnLayout,
    /// Threads (`null`: tract's process-wide executor).
    pub threads: Option<usize>,
}

/// A saved CNN plan record: per session (network and resolution) the engine, tract's layout and the threads,
/// and per f32 layer shape the kernel row it ran, for one kernel ISA level. Build one from a session
/// ([`crate::cnn::PlanReport::saved`]), save it with [`SavedPlans::to_json`], read it back with
/// [`SavedPlans::from_json`], and give it to later sessions as [`crate::cnn::PlanSource::Saved`]: they make
/// the same plans without timing anything, so every run with it gives the same bits.
///
/// ```json
/// {
///   "format": "tensorholo.cnn-plans",
///   "version": 2,
///   "isa": "avx512vnni",
///   "origin": "tuned by tensorholo 0.1.0 (2 threads available)",
///   "sessions": [{ "network": "hologram-cnn-8-f32-in4", "resolution": [384, 384],
///                  "engine": "native", "layout": "channels-first", "threads": 2 }],
///   "rows": [{ "c_in": 24, "c_out": 24, "algorithms": "auto", "row": "conv3x3.f32.wino4x4.24x1.avx512" }]
/// }
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedPlans {
    /// [`SAVED_PLANS_FORMAT`].
    pub format: String,
    /// [`SAVED_PLANS_VERSION`].
    pub version: u32,
    /// The kernel ISA level the rows are for (`avx512vnni`, `avx2`, `neondot`, `scalar`, …).
    pub isa: String,
    /// How the record was made, in words (e.g. `tuned by tensorholo 0.1.0 on 2 threads`); not read.
    pub origin: String,
    /// Per session: engine, layout, threads.
    pub sessions: Vec<SavedSession>,
    /// Per f32 layer shape: the kernel row.
    pub rows: Vec<SavedRow>,
}

impl SavedPlans {
    /// An empty record for kernel ISA level `isa`, made as `origin` says.
    pub(crate) fn new(isa: &str, origin: &str) -> Self {
        Self {
            format: SAVED_PLANS_FORMAT.into(),
            version: SAVED_PLANS_VERSION,
            isa: isa.into(),
            origin: origin.into(),
            sessions: Vec::new(),
            rows: Vec::new(),
        }
    }

    /// Reads a record from its JSON text (version 1 or 2, returned as version 2) and checks it
    /// (`SavedPlans::validate`).
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`tuning`) for text that is not such a record (not JSON, an
    /// unknown or missing key, another format or version) or fails the checks, naming the entry.
    pub fn from_json(text: &str) -> Result<Self> {
        let mut plans: Self = crate::io::parse_json_object(text, "a saved-plans record")
            .map_err(|e| invalid("tuning", format!("not a {SAVED_PLANS_FORMAT} file: {e}")))?;
        plans.validate()?;
        // Read as this version: written back, the rows say `auto` where a version 1 file said `any`.
        plans.version = SAVED_PLANS_VERSION;
        Ok(plans)
    }

    /// Reads a record from a file (at most the input limit, [`crate::io::InputLimits::max_file_bytes`]).
    ///
    /// Errors: [`HoloError::Io`] where the file cannot be read; [`HoloError::InvalidData`] above the limit;
    /// [`HoloError::InvalidParameter`] (`tuning`) as [`SavedPlans::from_json`], naming the file.
    pub fn read(path: &std::path::Path) -> Result<Self> {
        let text = crate::io::read_text(path)?;
        Self::from_json(&text).map_err(|e| match e {
            crate::HoloError::InvalidParameter { name, reason } => {
                crate::HoloError::InvalidParameter {
                    name,
                    reason: format!("`{}`: {reason}", path.display()),
                }
            }
            other => other,
        })
    }

    /// The record as indented JSON (what [`SavedPlans::from_json`] reads), entries in a stable order.
    pub fn to_json(&self) -> String {
        let mut sorted = self.clone();
        sorted.sort();
        // Plain data (strings, numbers, enums): serialising it cannot fail.
        serde_json::to_string_pretty(&sorted).unwrap_or_default() + "\n"
    }

    /// Checks the record: the format and version, a known ISA level, every row a compiled f32 kernel row of
    /// its algorithms that this level may run, channels in 1..=4096, every session a concrete engine and
    /// layout with 1..=[`MAX_CNN_THREADS`] threads (or `null`) at a non-empty resolution, and no entry twice.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`tuning`) naming the entry and what is wrong.
    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(invalid("tuning", what));
        if self.format != SAVED_PLANS_FORMAT {
            return bad(format!(
                "format is `{}`, expected `{SAVED_PLANS_FORMAT}`",
                self.format
            ));
        }
        if !(1..=SAVED_PLANS_VERSION).contains(&self.version) {
            return bad(format!(
                "version {} is not one this build reads (1 to {SAVED_PLANS_VERSION})",
                self.version
            ));
        }
        let isa = Isa::from_name(&self.isa).map_err(|e| invalid("tuning", format!("isa: {e}")))?;
        if self.rows.len() > MAX_ENTRIES || self.sessions.len() > MAX_ENTRIES {
            return bad(format!("more than {MAX_ENTRIES} entries"));
        }
        let mut keys = BTreeSet::new();
        for (i, r) in self.rows.iter().enumerate() {
            let at = format!(
                "rows[{i}] ({}→{}, {})",
                r.c_in,
                r.c_out,
                r.algorithms.name()
            );
            if !(1..=MAX_CHANNELS).contains(&r.c_in) || !(1..=MAX_CHANNELS).contains(&r.c_out) {
                return bad(format!("{at}: channels must be 1 to {MAX_CHANNELS}"));
            }
            if !keys.insert((r.c_in, r.c_out, r.algorithms)) {
                return bad(format!("{at}: this layer shape is listed twice"));
            }
            if row_info(isa, r).is_none() {
                return bad(format!(
                    "{at}: `{}` is not an f32 kernel row of {} that {} may run in this build",
                    r.row,
                    r.algorithms.name(),
                    isa.name()
                ));
            }
        }
        let mut sessions = BTreeSet::new();
        for (i, s) in self.sessions.iter().enumerate() {
            let [h, w] = s.resolution;
            let at = format!("sessions[{i}] ({} at {h}×{w})", s.network);
            if h == 0 || w == 0 || h.checked_mul(w).is_none() {
                return bad(format!("{at}: the resolution must be non-empty"));
            }
            if s.network.is_empty() || s.network.len() > 256 {
                return bad(format!("{at}: the network name must be 1 to 256 bytes"));
            }
            if s.engine == CnnEngine::Auto || s.layout == CnnLayout::Auto {
                return bad(format!(
                    "{at}: engine and layout must be what ran, not `auto`"
                ));
            }
            if let Some(t) = s.threads {
                if !(1..=MAX_CNN_THREADS).contains(&t) {
                    return bad(format!(
                        "{at}: threads must be 1 to {MAX_CNN_THREADS} (or null), got {t}"
                    ));
                }
            }
            if !sessions.insert((s.network.as_str(), s.resolution)) {
                return bad(format!("{at}: this session is listed twice"));
            }
        }
        Ok(())
    }

    /// The row saved for a `c_in → c_out` layer chosen among `algorithms`, if any.
    pub(crate) fn row(&self, c_in: usize, c_out: usize, algorithms: ConvAlgorithm) -> Option<&str> {
        self.rows
            .iter()
            .find(|r| (r.c_in, r.c_out, r.algorithms) == (c_in, c_out, algorithms))
            .map(|r| r.row.as_str())
    }

    /// The session saved for `network` at `resolution`, if any.
    pub(crate) fn session(&self, network: &str, resolution: [usize; 2]) -> Option<&SavedSession> {
        self.sessions
            .iter()
            .find(|s| s.network == network && s.resolution == resolution)
    }

    /// Adds `other`'s entries, replacing this record's entries of the same key (a later tuning of the same
    /// shape or session wins). Errors: [`HoloError::InvalidParameter`] (`tuning`) where the two records are
    /// for different ISA levels.
    pub fn merge(&mut self, other: &SavedPlans) -> Result<()> {
        if other.isa != self.isa {
            return Err(invalid(
                "tuning",
                format!(
                    "cannot merge plans for {} into plans for {}",
                    other.isa, self.isa
                ),
            ));
        }
        for r in &other.rows {
            self.rows
                .retain(|m| (m.c_in, m.c_out, m.algorithms) != (r.c_in, r.c_out, r.algorithms));
            self.rows.push(r.clone());
        }
        for s in &other.sessions {
            self.sessions.retain(|m| {
                (m.network.as_str(), m.resolution) != (s.network.as_str(), s.resolution)
            });
            self.sessions.push(s.clone());
        }
        self.sort();
        Ok(())
    }

    /// Checks the record may drive plans on kernel ISA level `isa` (the level the native engine runs).
    /// Errors: [`HoloError::InvalidParameter`] (`tuning`) naming both levels and how to make a new record.
    pub(crate) fn check_isa(&self, isa: Isa) -> Result<()> {
        if self.isa == isa.name() {
            return Ok(());
        }
        Err(invalid(
            "tuning",
            format!(
                "the saved plans were made for the {} kernels, and this CPU runs {}: tune again on this \
                 machine (`--tune`, or PlanSource::Tune) or leave the file out to use the plan table",
                self.isa,
                isa.name()
            ),
        ))
    }

    fn sort(&mut self) {
        self.rows.sort_by_key(|r| (r.c_in, r.c_out, r.algorithms));
        self.sessions
            .sort_by(|a, b| (&a.network, a.resolution).cmp(&(&b.network, b.resolution)));
    }
}

/// The compiled f32 row `r.row` where `isa` may run it for `r`'s shape and algorithms.
fn row_info(isa: Isa, r: &SavedRow) -> Option<&'static tensorholo_kernels::KernelInfo> {
    r.algorithms
        .algorithms()
        .iter()
        .flat_map(|&alg| registry::f32_rows_of(isa, r.c_out, alg))
        .find(|k| k.name == r.row)
}

/// The name a saved session gives a hologram CNN: `<kind>-<layers>-<precision>-in<channels>` (e.g.
/// `hologram-cnn-8-f32-in4`, `hologram-cnn-8-int8-qdq-conv-in20`): what decides its plans (depth, weight format,
/// input channels), not its weights, so that a retrained file of the same shape reuses the entry.
pub(crate) fn network_key(model: &crate::model::HologramModel) -> String {
    let md = model.metadata();
    format!(
        "{}-{}-{}-in{}",
        md.kind.metadata_name(),
        md.layers,
        md.precision,
        model.input_channels()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HoloError;

    fn sample() -> SavedPlans {
        let isa = Isa::detect();
        let direct = registry::f32_rows_of(isa, 24, tensorholo_kernels::Algorithm::Direct)
            .next()
            .unwrap();
        let mut p = SavedPlans::new(isa.name(), "test");
        p.rows.push(SavedRow {
            c_in: 24,
            c_out: 24,
            algorithms: ConvAlgorithm::Auto,
            row: direct.name.into(),
        });
        p.sessions.push(SavedSession {
            network: "hologram-cnn-8-f32-in4".into(),
            resolution: [384, 384],
            engine: CnnEngine::Native,
            layout: CnnLayout::ChannelsFirst,
            threads: Some(2),
        });
        p
    }

    /// Version 2 writes the one algorithm enum's `auto`; a version 1 file, whose rows said `any`, reads as
    /// the same plans.
    #[test]
    fn version_1_files_read_as_version_2() {
        let p = sample();
        let json = p.to_json();
        assert!(json.contains("\"version\": 2"), "{json}");
        assert!(json.contains("\"algorithms\": \"auto\""), "{json}");
        let v1 = json
            .replace("\"version\": 2", "\"version\": 1")
            .replace("\"algorithms\": \"auto\"", "\"algorithms\": \"any\"");
        let back = SavedPlans::from_json(&v1).unwrap();
        assert_eq!(back, p, "read as version 2");
    }

    #[test]
    fn a_record_reads_back_what_it_wrote() {
        let p = sample();
        let back = SavedPlans::from_json(&p.to_json()).unwrap();
        assert_eq!(back, p);
        assert_eq!(
            back.row(24, 24, ConvAlgorithm::Auto),
            Some(p.rows[0].row.as_str())
        );
        assert_eq!(back.row(24, 24, ConvAlgorithm::Direct), None);
        assert_eq!(
            back.session("hologram-cnn-8-f32-in4", [384, 384])
                .unwrap()
                .threads,
            Some(2)
        );
        assert!(back.session("hologram-cnn-8-f32-in4", [384, 385]).is_none());
        // A byte-order mark is accepted.
        assert_eq!(
            SavedPlans::from_json(&format!("\u{feff}{}", p.to_json())).unwrap(),
            p
        );
    }

    #[test]
    fn bad_records_are_refused_naming_the_entry() {
        let refused = |edit: &dyn Fn(&mut SavedPlans), needle: &str| {
            let mut p = sample();
            edit(&mut p);
            let e = SavedPlans::from_json(&p.to_json()).unwrap_err();
            assert!(
                matches!(e, HoloError::InvalidParameter { name: "tuning", .. }),
                "{e}"
            );
            assert!(e.to_string().contains(needle), "{needle}: {e}");
        };
        refused(&|p| p.format = "other".into(), "format is `other`");
        refused(&|p| p.version = 3, "version 3");
        refused(&|p| p.isa = "avx9".into(), "isa");
        refused(
            &|p| p.rows[0].row = "conv3x3.f32.nope".into(),
            "`conv3x3.f32.nope`",
        );
        refused(
            &|p| p.rows[0].algorithms = ConvAlgorithm::Winograd4x4,
            "rows[0]",
        );
        refused(&|p| p.rows[0].c_in = 0, "channels");
        refused(&|p| p.rows.push(p.rows[0].clone()), "twice");
        refused(&|p| p.sessions[0].threads = Some(0), "threads");
        refused(
            &|p| p.sessions[0].threads = Some(MAX_CNN_THREADS + 1),
            "threads",
        );
        refused(&|p| p.sessions[0].engine = CnnEngine::Auto, "not `auto`");
        refused(&|p| p.sessions[0].layout = CnnLayout::Auto, "not `auto`");
        refused(&|p| p.sessions[0].resolution = [0, 4], "non-empty");
        refused(&|p| p.sessions.push(p.sessions[0].clone()), "twice");
        // Not JSON, an unknown key, a missing key.
        for text in [
            "not json",
            r#"{"format":"tensorholo.cnn-plans"}"#,
            &sample()
                .to_json()
                .replacen("\"origin\"", "\"extra\": 1, \"origin\"", 1),
        ] {
            let e = SavedPlans::from_json(text).unwrap_err();
            assert!(
                e.to_string().contains("not a tensorholo.cnn-plans file"),
                "{e}"
            );
        }
    }

    #[test]
    fn merging_replaces_entries_of_the_same_key_and_keeps_the_others() {
        let mut a = sample();
        let mut b = sample();
        b.sessions[0].threads = Some(1);
        b.sessions.push(SavedSession {
            resolution: [1080, 1920],
            ..b.sessions[0].clone()
        });
        a.merge(&b).unwrap();
        assert_eq!(a.sessions.len(), 2);
        assert_eq!(
            a.session("hologram-cnn-8-f32-in4", [384, 384])
                .unwrap()
                .threads,
            Some(1)
        );
        assert_eq!(a.rows.len(), 1);
        let mut other = sample();
        other.isa = "scalar".into();
        if a.isa != "scalar" {
            assert!(a.merge(&other).is_err());
        }
        assert!(a.check_isa(Isa::detect()).is_ok());
    }
}
