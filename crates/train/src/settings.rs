//! The settings of a training run that do not depend on the model, and
//! their defaults, written once: the builder, the training request, the
//! command line, the Python package and the shard commands all start from
//! [`RunSettings::default`], so the same request gives the same file
//! whichever door it came through.

use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The seed of a run that names none (and trains on no shards, which
/// bring their own).
pub const DEFAULT_SEED: u64 = 1;

/// Seed, calibration and validation sizes, interval level, certificate
/// confidence and failure allowance of one training run.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `seed` | `None`: 1, or the shards' seed | any |
/// | `validation` (r) | 1000 | records for the validation report; 0: none |
/// | `calibration` | 4000 | records for the conformal intervals; 0: none (adaptive intervals need 100) |
/// | `alpha` | 0.1 | interval miscoverage, in (0, 1) |
/// | `delta` | 1e-3 | confidence of the Hoeffding bound, in (0, 1) |
/// | `max_failure_fraction` | 0.01 | share of failed records tolerated, in [0, 1) |
///
/// With 4000 calibration records the intervals' coverage on fresh records
/// stays within about 2 points of the level (docs/accuracy.md).
///
/// ```
/// use twostage::RunSettings;
/// let settings = RunSettings { alpha: 0.05, ..RunSettings::default() };
/// assert_eq!(settings.validation, 1000);
/// assert_eq!(settings.seed_or_default(), 1);
/// assert!(RunSettings { alpha: 1.5, ..settings }.check().is_err());
/// # Ok::<(), twostage::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSettings {
    /// Seed of every random choice of the run; `None` is [`DEFAULT_SEED`],
    /// or the seed of the shards trained on.
    pub seed: Option<u64>,
    /// Records of the validation report.
    pub validation: usize,
    /// Records of the conformal intervals.
    pub calibration: usize,
    /// Interval miscoverage: 0.1 gives 90% intervals.
    pub alpha: f64,
    /// Confidence parameter of the Hoeffding bound.
    pub delta: f64,
    /// Share of failed records tolerated in each role's chart.
    pub max_failure_fraction: f64,
}

impl Default for RunSettings {
    fn default() -> Self {
        Self {
            seed: None,
            validation: 1000,
            calibration: 4000,
            alpha: 0.1,
            delta: 1e-3,
            max_failure_fraction: 0.01,
        }
    }
}

impl RunSettings {
    /// The seed, or [`DEFAULT_SEED`] when none was set.
    pub fn seed_or_default(&self) -> u64 {
        self.seed.unwrap_or(DEFAULT_SEED)
    }

    /// Check every value against its range.
    ///
    /// # Errors
    /// A setting ([`Error::setting`]) naming the first value out of range.
    pub fn check(&self) -> Result<()> {
        let invalid = |name: &'static str, value: f64, reason: &str| {
            Err(Error::setting(name, value.to_string(), reason))
        };
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return invalid("alpha", self.alpha, "must lie in (0, 1)");
        }
        if !(self.delta > 0.0 && self.delta < 1.0) {
            return invalid("delta", self.delta, "must lie in (0, 1)");
        }
        if !(0.0..1.0).contains(&self.max_failure_fraction) {
            return invalid(
                "max_failure_fraction",
                self.max_failure_fraction,
                "must lie in [0, 1)",
            );
        }
        Ok(())
    }
}
