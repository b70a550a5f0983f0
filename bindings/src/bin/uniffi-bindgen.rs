//! The crate's own uniffi binding generator, so that no separate tool install is needed (same uniffi
//! version as the library, which the generated code's checksums require).
//!
//! Library mode, e.g. `uniffi-bindgen generate --library libtensorholo_ffi.so --language kotlin --out-dir out`
//! (`bindings/generate.sh` drives it). Built only with the crate feature `cli`.

fn main() {
    uniffi::uniffi_bindgen_main()
}
