//! The machine's load around a benchmark. Other work on the machine skews every time a
//! benchmark takes, so each one reads the one-minute load average (`/proc/loadavg`) when it
//! starts and when it ends, records both beside the machine and the commit, and refuses to
//! run when the load at the start is above a limit, unless forced; a forced run says so in
//! its output.

use nldf_core::host::Machine;

use crate::error::{Error, Result};

/// The load limit by default: on a 2-core machine, half a core busy with other work.
pub const DEFAULT_MAX_LOAD: f64 = 0.5;

/// Whether a benchmark may run at the machine's load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadGate {
    /// The highest one-minute load at the start that the benchmark accepts.
    pub max_load: f64,
    /// Run anyway above `max_load`, noting the load in the output.
    pub force: bool,
}

impl Default for LoadGate {
    fn default() -> Self {
        LoadGate {
            max_load: DEFAULT_MAX_LOAD,
            force: false,
        }
    }
}

impl LoadGate {
    /// A gate that admits any load without noting it as forced (tests and callers that
    /// time nothing they report).
    pub fn open() -> LoadGate {
        LoadGate {
            max_load: f64::INFINITY,
            force: false,
        }
    }

    /// The decision for a load reading at the start: `Ok(None)` to run, `Ok(Some(load))` to
    /// run forced at `load`, or [`Error::Busy`]. An unreadable load (`None`) runs, and the
    /// output says the load is unknown.
    pub fn decide(&self, load: Option<f64>) -> Result<Option<f64>> {
        if self.max_load.is_nan() || self.max_load < 0.0 {
            return Err(Error::Argument(format!(
                "--max-load must be zero or more, got {}",
                self.max_load
            )));
        }
        match load {
            Some(load) if load > self.max_load => {
                if self.force {
                    Ok(Some(load))
                } else {
                    Err(Error::Busy {
                        load,
                        max_load: self.max_load,
                    })
                }
            }
            _ => Ok(None),
        }
    }

    /// The machine with its load read now, admitted by [`LoadGate::decide`]: the limit and
    /// a forced load are recorded in it.
    pub fn admit(&self) -> Result<Machine> {
        let mut machine = Machine::here();
        self.admit_machine(&mut machine)?;
        Ok(machine)
    }

    /// [`LoadGate::admit`] on a machine already read (its `load_average_1m` is the
    /// reading).
    pub fn admit_machine(&self, machine: &mut Machine) -> Result<()> {
        machine.forced_at_load = self.decide(machine.load_average_1m)?;
        machine.max_load = self.max_load.is_finite().then_some(self.max_load);
        Ok(())
    }
}

/// The load part of the machine's table cell: the load at the start and at the end, and
/// whether the run was forced above its limit.
pub fn load_text(m: &Machine) -> String {
    let load = |l: Option<f64>| l.map_or_else(|| "unknown".into(), |l| format!("{l:.2}"));
    let mut text = format!(
        "load {} at the start, {} at the end",
        load(m.load_average_1m),
        load(m.load_average_1m_after)
    );
    if let Some(max) = m.max_load {
        text += &format!(" (limit {max:.2})");
    }
    if let Some(forced) = m.forced_at_load {
        text += &format!(", forced at load {forced:.2}");
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine(load: Option<f64>) -> Machine {
        Machine {
            cpu: "test cpu".into(),
            cores: 2,
            rayon_threads: 2,
            commit: "abc1234".into(),
            date_unix_s: 0,
            load_average_1m: load,
            load_average_1m_after: None,
            max_load: None,
            forced_at_load: None,
        }
    }

    #[test]
    fn a_load_above_the_limit_is_refused_in_one_line_naming_the_load_and_the_flag() {
        let gate = LoadGate::default();
        let e = gate.decide(Some(1.83)).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, Error::Busy { .. }), "{e:?}");
        assert!(text.contains("1.83"), "{text}");
        assert!(text.contains("--max-load 0.50"), "{text}");
        assert!(text.contains("--force"), "{text}");
        assert!(!text.contains('\n'), "{text}");
    }

    #[test]
    fn a_load_at_or_below_the_limit_runs_unforced() {
        let gate = LoadGate::default();
        assert_eq!(gate.decide(Some(0.1)).unwrap(), None);
        assert_eq!(gate.decide(Some(DEFAULT_MAX_LOAD)).unwrap(), None);
        // No /proc/loadavg: the run goes ahead, its load written as unknown.
        assert_eq!(gate.decide(None).unwrap(), None);
    }

    #[test]
    fn force_runs_above_the_limit_and_the_output_says_so() {
        let gate = LoadGate {
            max_load: 0.5,
            force: true,
        };
        assert_eq!(gate.decide(Some(2.4)).unwrap(), Some(2.4));
        assert_eq!(gate.decide(Some(0.2)).unwrap(), None);
        let mut m = machine(Some(2.4));
        gate.admit_machine(&mut m).unwrap();
        m.load_average_1m_after = Some(2.1);
        assert_eq!(m.forced_at_load, Some(2.4));
        assert_eq!(
            load_text(&m),
            "load 2.40 at the start, 2.10 at the end (limit 0.50), forced at load 2.40"
        );
        let json = serde_json::to_value(&m).unwrap();
        assert_eq!(json["forced_at_load"], 2.4);
        assert_eq!(json["load_average_1m_after"], 2.1);
    }

    #[test]
    fn an_unforced_machine_says_nothing_of_force() {
        let mut m = machine(Some(0.3));
        LoadGate::default().admit_machine(&mut m).unwrap();
        assert_eq!(
            load_text(&m),
            "load 0.30 at the start, unknown at the end (limit 0.50)"
        );
        assert!(
            LoadGate::default()
                .admit_machine(&mut machine(Some(0.7)))
                .is_err()
        );
    }

    #[test]
    fn a_negative_or_nan_limit_is_refused() {
        for max_load in [-0.1, f64::NAN] {
            let gate = LoadGate {
                max_load,
                force: false,
            };
            assert!(matches!(gate.decide(Some(0.0)), Err(Error::Argument(_))));
        }
    }
}
