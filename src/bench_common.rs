//! What the benchmark commands share: when a benchmark may run, how it repeats its
//! timings, and how it shows what it wrote.

use nldf_bench::Written;

/// When a benchmark may run: the machine's load at the start.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct LoadArgs {
    /// Refuse to run when the one-minute load average (/proc/loadavg) at the start is above
    /// this; the default allows half a core of other work on a 2-core machine.
    #[arg(long, default_value_t = nldf_bench::load::DEFAULT_MAX_LOAD)]
    pub max_load: f64,
    /// Run even when the load is above --max-load; the results say "forced at load X".
    #[arg(long)]
    pub force: bool,
}

impl LoadArgs {
    /// The benchmark's load gate.
    pub fn gate(&self) -> nldf_bench::load::LoadGate {
        nldf_bench::load::LoadGate {
            max_load: self.max_load,
            force: self.force,
        }
    }
}

/// How a benchmark with speed ratios repeats its timings, and when it may run.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct TimingArgs {
    /// Interleaved rounds (A B A B ...) behind every speed ratio: each round gives one ratio,
    /// and the median with the smallest and largest is reported ("no difference" where they
    /// reach 1.0).
    #[arg(long, default_value_t = nldf_bench::repeats::DEFAULT_PAIRS)]
    pub pairs: usize,
    #[command(flatten)]
    pub load: LoadArgs,
}

/// Prints a benchmark's Markdown and the files it wrote.
pub fn print_written(written: &Written) {
    print!("{}", written.markdown);
    println!(
        "wrote {} and {}",
        written.json.display(),
        written.md.display()
    );
    for plot in &written.plots {
        println!("wrote {}", plot.display());
    }
}
