#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ugv_fuzz_targets::plan_json(data));
