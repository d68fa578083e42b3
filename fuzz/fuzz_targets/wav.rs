//! libFuzzer target: nldf's wav reader (`nldf_tests::fuzz::wav`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::wav(data) {
        panic!("{broken}");
    }
});
