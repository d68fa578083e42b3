//! Where a stage's wall-clock time goes: named parts (teacher steps, the teacher's targets
//! for recorded frames and for pseudo views, student steps, validation, checkpoints), kept
//! in `timing.json` beside the checkpoint and added to on resume, so that a recipe's cost can
//! be read part by part instead of guessed from its total.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::Result;

/// The breakdown file beside a checkpoint.
pub const TIMING_FILE: &str = "timing.json";

/// One named part and its seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimePart {
    pub what: String,
    pub seconds: f64,
    /// How many times it ran (steps, validations, views), 0 where not counted.
    #[serde(default)]
    pub count: usize,
}

/// Seconds spent per part, in the order the parts first appeared.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    pub parts: Vec<TimePart>,
}

impl Timing {
    /// Adds `seconds` (and `count` runs) to part `what`.
    pub fn add(&mut self, what: &str, seconds: f64, count: usize) {
        let seconds = if seconds.is_finite() {
            seconds.max(0.0)
        } else {
            0.0
        };
        match self.parts.iter_mut().find(|p| p.what == what) {
            Some(p) => {
                p.seconds += seconds;
                p.count += count;
            }
            None => self.parts.push(TimePart {
                what: what.to_string(),
                seconds,
                count,
            }),
        }
    }

    /// Adds every part of `other`, each name prefixed with `prefix`.
    pub fn absorb(&mut self, prefix: &str, other: &Timing) {
        for p in &other.parts {
            self.add(&format!("{prefix}{}", p.what), p.seconds, p.count);
        }
    }

    /// Seconds of all parts.
    pub fn total(&self) -> f64 {
        self.parts.iter().map(|p| p.seconds).sum()
    }

    /// The breakdown in `dir`, or an empty one when it has none yet.
    pub fn open(dir: &Path) -> Result<Timing> {
        let path = dir.join(TIMING_FILE);
        if path.is_file() {
            Ok(nldf_core::files::read_json(&path)?)
        } else {
            Ok(Timing::default())
        }
    }

    /// Writes the breakdown to `dir/timing.json` (atomically).
    pub fn save(&self, dir: &Path) -> Result<()> {
        Ok(nldf_core::files::write_json(&dir.join(TIMING_FILE), self)?)
    }

    /// One line per part: seconds, minutes, share of the total and count.
    pub fn lines(&self) -> Vec<String> {
        let total = self.total().max(1e-9);
        let mut out: Vec<String> = self
            .parts
            .iter()
            .map(|p| {
                let count = if p.count > 0 {
                    format!("  ({} x)", p.count)
                } else {
                    String::new()
                };
                format!(
                    "{:<44} {:>8.1} s {:>6.2} min {:>5.1} %{count}",
                    p.what,
                    p.seconds,
                    p.seconds / 60.0,
                    100.0 * p.seconds / total
                )
            })
            .collect();
        out.push(format!(
            "{:<44} {:>8.1} s {:>6.2} min",
            "total",
            self.total(),
            self.total() / 60.0
        ));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_add_up_and_round_trip() {
        let mut t = Timing::default();
        t.add("steps", 2.0, 1);
        t.add("validation", 1.0, 1);
        t.add("steps", 3.0, 1);
        t.add("bad", f64::NAN, 0);
        assert_eq!(t.parts[0].seconds, 5.0);
        assert_eq!(t.parts[0].count, 2);
        assert_eq!(t.total(), 6.0);
        let dir = tempfile::tempdir().unwrap();
        t.save(dir.path()).unwrap();
        assert_eq!(Timing::open(dir.path()).unwrap(), t);
        let mut all = Timing::default();
        all.absorb("student: ", &t);
        assert_eq!(all.parts[1].what, "student: validation");
        assert!(t.lines().last().unwrap().contains("6.0 s"));
    }
}
