//! Speed ratios from interleaved repeats. Two ways of doing the same work, A and B, are
//! timed in turns (A B A B ...); each pair of times gives one ratio, and a benchmark reports
//! the median of the per-pair ratios with their spread, the smallest and the largest
//! ([`Ratio`]). Taking turns lets a change in the machine's load touch both alike, and the
//! spread shows what is left of it.
//!
//! The verdict is a sign test: a ratio counts as a difference only when every pair falls on
//! the same side of 1.0, that is when the spread (minimum to maximum) does not reach 1.0.
//! Were A and B equally fast, each pair would fall on either side with even odds, so `n`
//! pairs would all agree by chance with probability `2 * 0.5^n`; with fewer than
//! [`MIN_PAIRS_FOR_A_DIFFERENCE`] pairs that is too likely, and the verdict is "no
//! difference" however the pairs fall. Otherwise the ratio is written as "no difference"
//! only where the spread reaches 1.0, its numbers beside it.

use serde::Serialize;

use crate::error::{Error, Result};

/// Pairs a benchmark times by default.
pub const DEFAULT_PAIRS: usize = 5;

/// The fewest pairs that can show a difference: with fewer, every pair falls on one side
/// too often by chance alone (`2 * 0.5^n`), so the verdict is "no difference" whatever
/// the ratios.
pub const MIN_PAIRS_FOR_A_DIFFERENCE: usize = 5;

/// The fewest pairs a benchmark accepts (one pair has no spread).
pub const MIN_PAIRS: usize = 2;

/// What the per-pair ratios say.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every per-pair ratio is above 1.0.
    Above,
    /// Every per-pair ratio is below 1.0.
    Below,
    /// The spread reaches 1.0: the pairs disagree on which side is larger.
    NoDifference,
}

/// A ratio measured over interleaved pairs: the median of the per-pair ratios and their
/// spread, the smallest and the largest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ratio {
    /// Median of the per-pair ratios.
    pub median: f64,
    /// Smallest per-pair ratio.
    pub min: f64,
    /// Largest per-pair ratio.
    pub max: f64,
    /// How many pairs.
    pub pairs: usize,
    /// [`Verdict::NoDifference`] where `min <= 1 <= max`, or with fewer than
    /// [`MIN_PAIRS_FOR_A_DIFFERENCE`] pairs.
    pub verdict: Verdict,
}

impl Ratio {
    /// The ratio of `numerator / denominator` over pairs `(numerator, denominator)`, e.g.
    /// `(time of B, time of A)` for how many times as fast A is as B. Every value must be
    /// finite and positive, and there must be at least one pair.
    pub fn of_pairs(pairs: &[(f64, f64)]) -> Result<Ratio> {
        let ratios = pairs
            .iter()
            .map(|&(n, d)| {
                if n.is_finite() && d.is_finite() && n > 0.0 && d > 0.0 {
                    Ok(n / d)
                } else {
                    Err(Error::Argument(format!(
                        "a timed pair holds {n} and {d}: times must be finite and positive"
                    )))
                }
            })
            .collect::<Result<Vec<f64>>>()?;
        Ratio::of_ratios(&ratios)
    }

    /// The median and spread of per-pair ratios that are already divided.
    pub fn of_ratios(ratios: &[f64]) -> Result<Ratio> {
        if ratios.is_empty() {
            return Err(Error::Argument(
                "a ratio needs at least one timed pair".into(),
            ));
        }
        if let Some(bad) = ratios.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
            return Err(Error::Argument(format!(
                "a per-pair ratio is {bad}: ratios must be finite and positive"
            )));
        }
        let min = ratios.iter().copied().fold(f64::INFINITY, f64::min);
        let max = ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Ok(Ratio {
            median: nldf_core::stats::median(ratios),
            min,
            max,
            pairs: ratios.len(),
            verdict: if ratios.len() < MIN_PAIRS_FOR_A_DIFFERENCE {
                Verdict::NoDifference
            } else {
                verdict(min, max)
            },
        })
    }

    /// Whether every pair agrees on the side of 1.0.
    pub fn differs(&self) -> bool {
        self.verdict != Verdict::NoDifference
    }

    /// The ratio as a table cell: `1.10x (1.02-1.18, 5 pairs)`, or
    /// `no difference (1.03x, 0.97-1.12, 5 pairs)` where the spread reaches 1.0.
    pub fn cell(&self) -> String {
        let plural = if self.pairs == 1 { "" } else { "s" };
        let spread = format!(
            "{}-{}, {} pair{plural}",
            fmt(self.min),
            fmt(self.max),
            self.pairs
        );
        if self.differs() {
            format!("{}x ({spread})", fmt(self.median))
        } else {
            format!("no difference ({}x, {spread})", fmt(self.median))
        }
    }
}

/// The verdict of per-pair ratios spanning `min..=max`.
fn verdict(min: f64, max: f64) -> Verdict {
    if min > 1.0 {
        Verdict::Above
    } else if max < 1.0 {
        Verdict::Below
    } else {
        Verdict::NoDifference
    }
}

/// A ratio with two decimals, or three significant digits from 100 up (a speed-up of
/// hundreds).
fn fmt(r: f64) -> String {
    if r >= 100.0 {
        format!("{r:.0}")
    } else if r >= 10.0 {
        format!("{r:.1}")
    } else {
        format!("{r:.2}")
    }
}

/// `cell` of an optional ratio, empty where there is none.
pub fn cell(r: Option<&Ratio>) -> String {
    r.map_or_else(String::new, Ratio::cell)
}

/// Runs `a` and `b` in turns, `pairs` times each (A B A B ...); each call returns what it
/// measured (seconds, or any figure). Returns the pairs `(a, b)` in order.
pub fn interleave<T>(
    pairs: usize,
    mut a: impl FnMut(usize) -> Result<T>,
    mut b: impl FnMut(usize) -> Result<T>,
) -> Result<Vec<(T, T)>> {
    let mut out = Vec::with_capacity(pairs);
    for i in 0..pairs {
        let x = a(i)?;
        let y = b(i)?;
        out.push((x, y));
    }
    Ok(out)
}

/// Checks a `--pairs` count: at least [`MIN_PAIRS`].
pub fn check_pairs(pairs: usize) -> Result<()> {
    if pairs < MIN_PAIRS {
        return Err(Error::Argument(format!(
            "--pairs must be at least {MIN_PAIRS} (one pair has no spread), got {pairs}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_and_spread_are_those_of_the_per_pair_ratios() {
        // B takes 1.2, 1.1, 1.3, 1.15, 1.25 times as long as A in its pairs.
        let pairs = [(1.2, 1.0), (2.2, 2.0), (1.3, 1.0), (2.3, 2.0), (1.25, 1.0)];
        let r = Ratio::of_pairs(&pairs).unwrap();
        assert!((r.median - 1.2).abs() < 1e-12, "{r:?}");
        assert!((r.min - 1.1).abs() < 1e-12, "{r:?}");
        assert!((r.max - 1.3).abs() < 1e-12, "{r:?}");
        assert_eq!(r.pairs, 5);
        assert_eq!(r.verdict, Verdict::Above);
        assert_eq!(r.cell(), "1.20x (1.10-1.30, 5 pairs)");
    }

    #[test]
    fn a_spread_crossing_one_is_no_difference() {
        // The case of the int8 and fp32 times that swapped sides between pairs: the median
        // says 1.04x, one pair says the other one was faster.
        let r = Ratio::of_ratios(&[1.06, 1.04, 0.97, 1.10, 1.02]).unwrap();
        assert_eq!(r.verdict, Verdict::NoDifference);
        assert!(!r.differs());
        assert_eq!(r.cell(), "no difference (1.04x, 0.97-1.10, 5 pairs)");
        // A spread that touches 1.0 is no difference either.
        let r = Ratio::of_ratios(&[1.0, 1.2, 1.3]).unwrap();
        assert_eq!(r.verdict, Verdict::NoDifference);
        // Nor are too few pairs, however far from 1.0: four that agree prove little.
        let r = Ratio::of_ratios(&[3.0]).unwrap();
        assert_eq!(r.verdict, Verdict::NoDifference);
        assert_eq!(r.cell(), "no difference (3.00x, 3.00-3.00, 1 pair)");
        let r = Ratio::of_ratios(&[3.0, 3.1, 2.9, 3.05]).unwrap();
        assert_eq!(r.verdict, Verdict::NoDifference);
        let r = Ratio::of_ratios(&[3.0, 3.1, 2.9, 3.05, 3.2]).unwrap();
        assert_eq!(r.verdict, Verdict::Above);
    }

    #[test]
    fn every_pair_below_one_is_a_difference_the_other_way() {
        let r = Ratio::of_ratios(&[0.5, 0.45, 0.55, 0.52, 0.48, 0.5]).unwrap();
        assert_eq!(r.verdict, Verdict::Below);
        assert!((r.median - 0.5).abs() < 1e-12);
        assert_eq!(r.cell(), "0.50x (0.45-0.55, 6 pairs)");
    }

    #[test]
    fn large_ratios_keep_three_digits() {
        let r = Ratio::of_ratios(&[623.4, 610.0, 640.2, 615.0, 630.0]).unwrap();
        assert_eq!(r.cell(), "623x (610-640, 5 pairs)");
        let r = Ratio::of_ratios(&[9.84, 9.7, 10.2, 9.9, 9.6]).unwrap();
        assert_eq!(r.cell(), "9.84x (9.60-10.2, 5 pairs)");
    }

    #[test]
    fn bad_times_and_empty_samples_are_refused() {
        assert!(Ratio::of_pairs(&[]).is_err());
        assert!(Ratio::of_pairs(&[(1.0, 0.0)]).is_err());
        assert!(Ratio::of_pairs(&[(f64::NAN, 1.0)]).is_err());
        assert!(Ratio::of_ratios(&[1.0, f64::INFINITY]).is_err());
        assert!(check_pairs(1).is_err());
        assert!(check_pairs(MIN_PAIRS).is_ok());
    }

    #[test]
    fn interleave_takes_turns() {
        let order = std::cell::RefCell::new(Vec::new());
        let pairs = interleave(
            3,
            |i| {
                order.borrow_mut().push(format!("a{i}"));
                Ok(i)
            },
            |i| {
                order.borrow_mut().push(format!("b{i}"));
                Ok(10 + i)
            },
        )
        .unwrap();
        assert_eq!(pairs, [(0, 10), (1, 11), (2, 12)]);
        assert_eq!(order.into_inner(), ["a0", "b0", "a1", "b1", "a2", "b2"]);
    }
}
