//! Range checks of configuration values, shared by every configuration that nldf reads:
//! each error names the key whose value is wrong (`model.width must be in [1, 4096], got 0`).

use std::fmt::Display;

use crate::error::{Error, Result};

/// Largest network width the checks accept: far beyond any preset, small enough that a typo
/// cannot ask for terabytes.
pub const MAX_WIDTH: usize = 4096;

/// `Ok` when `lo <= value <= hi`, else an error naming `key` (NaN is out of every range).
pub fn in_range<T: PartialOrd + Display>(key: &str, value: T, lo: T, hi: T) -> Result<()> {
    if value >= lo && value <= hi {
        Ok(())
    } else {
        Err(Error::Argument(format!(
            "`{key}` must be in [{lo}, {hi}], got {value}"
        )))
    }
}

/// `Ok` when `lo <= value < hi`, else an error naming `key`.
pub fn in_range_open(key: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
    if value >= lo && value < hi {
        Ok(())
    } else {
        Err(Error::Argument(format!(
            "`{key}` must be in [{lo}, {hi}), got {value}"
        )))
    }
}

/// `Ok` when `value >= lo`, else an error naming `key`.
pub fn at_least(key: &str, value: usize, lo: usize) -> Result<()> {
    if value >= lo {
        Ok(())
    } else {
        Err(Error::Argument(format!(
            "`{key}` must be at least {lo}, got {value}"
        )))
    }
}

/// `Ok` for a finite `value > 0` (at most `hi`), else an error naming `key`.
pub fn positive(key: &str, value: f64, hi: f64) -> Result<()> {
    if value > 0.0 && value <= hi {
        Ok(())
    } else {
        Err(Error::Argument(format!(
            "`{key}` must be positive and at most {hi:e}, got {value}"
        )))
    }
}
