//! Facts about the machine nldf runs on, for benchmark reports and `nldf doctor`.

/// The CPU's model name, from `/proc/cpuinfo`, when it can be read.
pub fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    info.lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|m| m.trim().to_string())
}
