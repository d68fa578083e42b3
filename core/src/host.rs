//! Facts about the machine nldf runs on, for benchmark reports and `nldf doctor`: the CPU,
//! the load, this process's CPU time, and [`Machine`], what every benchmark records.

use serde::Serialize;

/// The CPU's model name, from `/proc/cpuinfo`, when it can be read.
pub fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    info.lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|m| m.trim().to_string())
}

/// The machine a benchmark ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub rayon_threads: usize,
    pub commit: String,
    pub date_unix_s: u64,
    /// `/proc/loadavg`'s one-minute load when the benchmark started (other work on the
    /// machine skews every figure).
    pub load_average_1m: Option<f64>,
    /// The same when the benchmark ended (`None` until [`Machine::record_end`]).
    pub load_average_1m_after: Option<f64>,
    /// The load at the start above which the benchmark refuses to run without `--force`.
    pub max_load: Option<f64>,
    /// The load at the start when it was above `max_load` and the benchmark ran anyway
    /// (`--force`); `None` when it was not forced.
    pub forced_at_load: Option<f64>,
}

impl Machine {
    /// Reads the CPU model (`/proc/cpuinfo`), core count, the git commit of the working
    /// directory (each `unknown` when it cannot be read) and the load now.
    pub fn here() -> Machine {
        let cpu = cpu_model().unwrap_or_else(|| "unknown".into());
        let commit = std::process::Command::new("git")
            .args(["rev-parse", "--short", "HEAD"])
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_else(|| "unknown".into());
        Machine {
            cpu,
            cores: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            rayon_threads: rayon::current_num_threads(),
            commit,
            date_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
            load_average_1m: load_average_1m(),
            load_average_1m_after: None,
            max_load: None,
            forced_at_load: None,
        }
    }

    /// Records the load when the benchmark ended.
    pub fn record_end(&mut self) {
        self.load_average_1m_after = load_average_1m();
    }
}

/// `/proc/loadavg`'s one-minute load average, `None` where it cannot be read.
pub fn load_average_1m() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
}

/// CPU seconds (user + system) this process has used, from `/proc/self/stat`.
pub fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name may hold spaces; fields restart after its closing parenthesis.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
