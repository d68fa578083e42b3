//! libFuzzer target: nldf's npy reader (`nldf_tests::fuzz::npy`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::npy(data) {
        panic!("{broken}");
    }
});
