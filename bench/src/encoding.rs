//! The positional encoding benchmark (`nldf bench encoding`): its sines and cosines three
//! ways (direct f32, the f32 double-angle climb, nldf's f64 climb), time per value and error
//! against f64.

use std::path::Path;

use nldf_core::host::Machine;
use nldf_train::reports::bench::{EncodingBench, bench_encoding};
use serde::Serialize;

use crate::error::Result;
use crate::load::LoadGate;
use crate::report::{Written, machine_cell, write_bench_files};

/// What the encoding benchmark measures.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct EncodingJob {
    /// Frequencies L.
    pub freqs: usize,
    /// The scene's coordinate range |x| for the first error column.
    pub range: f32,
    /// Timed repetitions (the median is reported).
    pub reps: usize,
    /// The load limit at the start.
    #[serde(skip)]
    pub load: LoadGate,
}

/// The encoding benchmark's report: `encoding.json`.
#[derive(Debug, Clone, Serialize)]
pub struct EncodingReport {
    /// `encoding`.
    pub bench: &'static str,
    pub machine: Machine,
    pub settings: EncodingJob,
    pub result: EncodingBench,
}

impl EncodingJob {
    /// Times and checks the variants, if the machine's load admits it.
    pub fn run(&self) -> Result<EncodingReport> {
        let mut machine = self.load.admit()?;
        let result = bench_encoding(self.freqs, self.range, self.reps);
        machine.record_end();
        Ok(EncodingReport {
            bench: "encoding",
            machine,
            settings: *self,
            result,
        })
    }
}

impl EncodingReport {
    /// Writes `encoding.json` and `encoding.md` into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        write_bench_files(out, "encoding", self, self.markdown())
    }

    /// One row per variant: time per value and the largest errors.
    pub fn markdown(&self) -> String {
        let result = &self.result;
        let mut md = format!(
            "Positional encoding, L = {}, {} values per call (a beam), one thread; error is the \
             largest difference from the exact sin(2^l x), cos(2^l x) in f64.\n\n\
             Machine: {}\n\n\
             | variant | ns per value | max error, abs(x) <= {} | max error, abs(x) <= 1e4 |\n\
             |---|---|---|---|\n",
            result.n_freqs,
            result.values_per_call,
            machine_cell(&self.machine),
            result.scene_range
        );
        for v in &result.variants {
            md.push_str(&format!(
                "| {} | {:.1} | {:.2e} | {:.2e} |\n",
                v.name, v.ns_per_value, v.max_error_scene, v.max_error_clamp
            ));
        }
        md
    }
}
