#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ugv_fuzz_targets::laser_frame(data));
