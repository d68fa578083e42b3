//! libFuzzer target: nldf's onnx reader (`nldf_tests::fuzz::onnx`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::onnx(data) {
        panic!("{broken}");
    }
});
