//! libFuzzer target: nldf's safetensors reader (`nldf_tests::fuzz::safetensors`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::safetensors(data) {
        panic!("{broken}");
    }
});
