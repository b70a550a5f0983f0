//! cargo-fuzz target `shard_record`: see `tensorholo_fuzz::shard_record` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::shard_record(data));
