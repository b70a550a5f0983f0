//! cargo-fuzz target `spot_plan`: see `tensorholo_fuzz::spot_plan` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::spot_plan(data));
