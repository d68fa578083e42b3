//! libFuzzer target: nldf's config reader (`nldf_tests::fuzz::config`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::config(data) {
        panic!("{broken}");
    }
});
