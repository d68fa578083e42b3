//! libFuzzer target: a dataset whose `transforms_train.json` is the input
//! (`nldf_tests::fuzz::transforms`), loaded and validated whole.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use nldf_tests::fuzz;

/// A valid tiny dataset in a folder that lives as long as the fuzzer.
fn dataset() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder").keep();
        nldf_tests::write_tiny_dataset(&dir);
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = fuzz::transforms(dataset(), data) {
        panic!("{broken}");
    }
});
