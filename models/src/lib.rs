//! # tensorholo-models
//!
//! The CNNs the `tensorholo` crate ships (Tensor Holography V2), as the bytes of their ONNX files, compiled in
//! with `include_bytes!`. `tensorholo` reads them through `tensorholo::model::embedded` (its cargo feature
//! `embedded-models`, on by default); this crate holds only the bytes, so that they travel as a package of
//! their own. What each network is, how it was trained and how well it does: the model card (`MODEL_CARD.md`,
//! this package's readme).
//!
//! - Always: the 8-layer RGB-D and LDI hologram CNNs and the DDPM pre-filter CNNs for SLM offsets of 6 and
//!   12 mm, each in f32 and int8 QDQ.
//! - Cargo features `models-15` and `models-30` (off by default): the 15- and 30-layer hologram CNNs, each with
//!   the 6 and 12 mm pre-filters trained on its holograms, f32 and int8 QDQ.
//! - Cargo feature `qop-models` (off by default): the int8 QOperator form of each of the above (only tract
//!   runs them).
//!
//! Each file is a `static` named after it ([`HOLO8_RGBD`] is `holo8_rgbd.onnx`); [`get`] finds one by file
//! name, [`files`] lists those of the build.
//!
//! ```
//! let bytes = tensorholo_models::get("holo8_rgbd.onnx").unwrap();
//! assert_eq!(bytes, tensorholo_models::HOLO8_RGBD);
//! assert!(tensorholo_models::files().any(|(name, _)| name == "prefilter_6mm.int8-qdq.onnx"));
//! ```
#![no_std]

/// One group of files: a `static` per file (`include_bytes!` of the file at the top of the package) and the
/// group's `(file name, bytes)` list, both present where `cfg(...)` holds (the list is empty elsewhere).
macro_rules! group {
    ($group:ident, cfg($cfg:meta), $what:literal, { $($ident:ident = $file:literal),* $(,)? }) => {
        $(
            #[cfg($cfg)]
            #[doc = concat!("`", $file, "`: ", $what, ".")]
            pub static $ident: &[u8] = include_bytes!(concat!("../", $file));
        )*
        #[cfg($cfg)]
        const $group: &[(&str, &[u8])] = &[$(($file, $ident)),*];
        #[cfg(not($cfg))]
        const $group: &[(&str, &[u8])] = &[];
    };
}

group!(BASE, cfg(all()), "always embedded", {
    HOLO8_RGBD = "holo8_rgbd.onnx",
    HOLO8_RGBD_INT8_QDQ = "holo8_rgbd.int8-qdq.onnx",
    HOLO8_LDI = "holo8_ldi.onnx",
    HOLO8_LDI_INT8_QDQ = "holo8_ldi.int8-qdq.onnx",
    PREFILTER_6MM = "prefilter_6mm.onnx",
    PREFILTER_6MM_INT8_QDQ = "prefilter_6mm.int8-qdq.onnx",
    PREFILTER_12MM = "prefilter_12mm.onnx",
    PREFILTER_12MM_INT8_QDQ = "prefilter_12mm.int8-qdq.onnx",
});

group!(BASE_QOP, cfg(feature = "qop-models"), "cargo feature `qop-models`", {
    HOLO8_RGBD_INT8_QOP = "holo8_rgbd.int8-qop.onnx",
    HOLO8_LDI_INT8_QOP = "holo8_ldi.int8-qop.onnx",
    PREFILTER_6MM_INT8_QOP = "prefilter_6mm.int8-qop.onnx",
    PREFILTER_12MM_INT8_QOP = "prefilter_12mm.int8-qop.onnx",
});

group!(HOLO15, cfg(feature = "models-15"), "cargo feature `models-15`", {
    HOLO15_RGBD = "holo15_rgbd.onnx",
    HOLO15_RGBD_INT8_QDQ = "holo15_rgbd.int8-qdq.onnx",
    PREFILTER_6MM_HOLO15 = "prefilter_6mm_holo15.onnx",
    PREFILTER_6MM_HOLO15_INT8_QDQ = "prefilter_6mm_holo15.int8-qdq.onnx",
    PREFILTER_12MM_HOLO15 = "prefilter_12mm_holo15.onnx",
    PREFILTER_12MM_HOLO15_INT8_QDQ = "prefilter_12mm_holo15.int8-qdq.onnx",
});

group!(HOLO15_QOP, cfg(all(feature = "models-15", feature = "qop-models")),
    "cargo features `models-15` and `qop-models`", {
    HOLO15_RGBD_INT8_QOP = "holo15_rgbd.int8-qop.onnx",
    PREFILTER_6MM_HOLO15_INT8_QOP = "prefilter_6mm_holo15.int8-qop.onnx",
    PREFILTER_12MM_HOLO15_INT8_QOP = "prefilter_12mm_holo15.int8-qop.onnx",
});

group!(HOLO30, cfg(feature = "models-30"), "cargo feature `models-30`", {
    HOLO30_RGBD = "holo30_rgbd.onnx",
    HOLO30_RGBD_INT8_QDQ = "holo30_rgbd.int8-qdq.onnx",
    PREFILTER_6MM_HOLO30 = "prefilter_6mm_holo30.onnx",
    PREFILTER_6MM_HOLO30_INT8_QDQ = "prefilter_6mm_holo30.int8-qdq.onnx",
    PREFILTER_12MM_HOLO30 = "prefilter_12mm_holo30.onnx",
    PREFILTER_12MM_HOLO30_INT8_QDQ = "prefilter_12mm_holo30.int8-qdq.onnx",
});

group!(HOLO30_QOP, cfg(all(feature = "models-30", feature = "qop-models")),
    "cargo features `models-30` and `qop-models`", {
    HOLO30_RGBD_INT8_QOP = "holo30_rgbd.int8-qop.onnx",
    PREFILTER_6MM_HOLO30_INT8_QOP = "prefilter_6mm_holo30.int8-qop.onnx",
    PREFILTER_12MM_HOLO30_INT8_QOP = "prefilter_12mm_holo30.int8-qop.onnx",
});

const GROUPS: [&[(&str, &[u8])]; 6] = [BASE, BASE_QOP, HOLO15, HOLO15_QOP, HOLO30, HOLO30_QOP];

/// Every file of this build: `(file name, bytes)`, in the order of the list above.
pub fn files() -> impl Iterator<Item = (&'static str, &'static [u8])> {
    GROUPS.into_iter().flatten().copied()
}

/// The bytes of the file named `name` (`"holo8_rgbd.onnx"`), `None` for a file this build does not have
/// (another name, or a file of a feature that is off). A `const fn`: usable in constants, where a missing file
/// can be a compile error.
pub const fn get(name: &str) -> Option<&'static [u8]> {
    let mut g = 0;
    while g < GROUPS.len() {
        let mut i = 0;
        while i < GROUPS[g].len() {
            let (file, bytes) = GROUPS[g][i];
            if eq(file.as_bytes(), name.as_bytes()) {
                return Some(bytes);
            }
            i += 1;
        }
        g += 1;
    }
    None
}

const fn eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::String;
    use std::vec::Vec;

    /// With every feature on, each `*.onnx` at the top of the package is embedded, once (a new shipped file
    /// needs a line here, and the package's `include` takes it).
    #[test]
    #[cfg(all(feature = "models-15", feature = "models-30", feature = "qop-models"))]
    fn every_file_is_embedded() {
        let mut on_disk: Vec<String> = std::fs::read_dir(env!("CARGO_MANIFEST_DIR"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .filter(|n| n.ends_with(".onnx"))
            .collect();
        on_disk.sort();
        let mut embedded: Vec<String> = super::files().map(|(n, _)| n.into()).collect();
        embedded.sort();
        assert_eq!(embedded, on_disk);
        for (name, bytes) in super::files() {
            assert_eq!(
                std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(name)).unwrap(),
                bytes
            );
        }
    }

    #[test]
    fn lookup() {
        assert_eq!(
            super::get("holo8_ldi.int8-qdq.onnx"),
            Some(super::HOLO8_LDI_INT8_QDQ)
        );
        assert_eq!(super::get("holo8_ldi.int8-qdq"), None);
        assert_eq!(
            super::get("holo15_rgbd.onnx").is_some(),
            cfg!(feature = "models-15")
        );
        assert_eq!(
            super::get("holo30_rgbd.int8-qop.onnx").is_some(),
            cfg!(all(feature = "models-30", feature = "qop-models"))
        );
    }
}
