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
/// | `validation` (r) | 1000 | records for the validation report (with `certify_within`, its first round); 0: none |
/// | `certify_within` | `Some(1.2)` | grow the validation until every certified RMSE is at most this many times the observed one, > 1; `None`: exactly `validation` records |
/// | `max_validation` | 1,000,000 | the most records growing may take, at least `validation` |
/// | `calibration` | 4000 | records for the conformal intervals; 0: none (adaptive intervals need 100) |
/// | `alpha` | 0.1 | interval miscoverage, in (0, 1) |
/// | `delta` | 1e-3 | confidence of the Hoeffding bound, in (0, 1) |
/// | `max_failure_fraction` | 0.01 | share of failed records tolerated, in [0, 1) |
///
/// With 4000 calibration records the intervals' coverage on fresh records
/// stays within about 2 points of the level (docs/accuracy.md). A
/// certificate of small errors needs many records (its margin cannot fall
/// below about `sigma ln(1/delta) / r` for errors bounded by `sigma`), so
/// by default the validation grows, where its records are simulated,
/// until the certificate a user reads is within 1.2 times the error seen;
/// records read from charts or shards cannot grow, and the report says
/// how many it would take.
///
/// ```
/// use twostage::RunSettings;
/// let settings = RunSettings { alpha: 0.05, ..RunSettings::default() };
/// assert_eq!(settings.validation, 1000);
/// assert_eq!(settings.certify_within, Some(1.2));
/// assert_eq!(settings.seed_or_default(), 1);
/// assert!(RunSettings { alpha: 1.5, ..settings.clone() }.check().is_err());
/// assert!(RunSettings { certify_within: Some(1.0), ..settings.clone() }.check().is_err());
/// assert!(RunSettings { max_validation: 10, ..settings }.check().is_err());
/// # Ok::<(), twostage::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSettings {
    /// Seed of every random choice of the run; `None` is [`DEFAULT_SEED`],
    /// or the seed of the shards trained on.
    pub seed: Option<u64>,
    /// Records of the validation report: with `certify_within`, its first
    /// round.
    pub validation: usize,
    /// Grow the validation, where its records are simulated, until every
    /// certified RMSE is at most this many times the observed one (each
    /// round as many records as the last predicts; the certificate holds
    /// at every r at once, so stopping when it is met keeps its
    /// confidence). `None`: exactly `validation` records.
    pub certify_within: Option<f64>,
    /// The most validation records growing may take.
    pub max_validation: usize,
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
            certify_within: Some(1.2),
            max_validation: 1_000_000,
            calibration: 4000,
            alpha: 0.1,
            delta: 1e-3,
            max_failure_fraction: 0.01,
        }
    }
}

impl RunSettings {
    /// The validation as a door's options ask for it: `validate` records
    /// exactly, unless `certify_within` grows them (from `validate`, else
    /// the default first round); neither: the default growth. The command
    /// line and Python read their options through it alike.
    ///
    /// ```
    /// use twostage::RunSettings;
    /// let grown = RunSettings::default().validation_asked(None, None, None);
    /// assert_eq!((grown.validation, grown.certify_within), (1000, Some(1.2)));
    /// let exact = RunSettings::default().validation_asked(Some(200), None, None);
    /// assert_eq!((exact.validation, exact.certify_within), (200, None));
    /// let both = RunSettings::default().validation_asked(Some(200), Some(1.5), Some(9000));
    /// assert_eq!((both.validation, both.certify_within, both.max_validation), (200, Some(1.5), 9000));
    /// ```
    pub fn validation_asked(
        self,
        validate: Option<usize>,
        certify_within: Option<f64>,
        max_validation: Option<usize>,
    ) -> Self {
        Self {
            validation: validate.unwrap_or(self.validation),
            certify_within: match (certify_within, validate) {
                (Some(k), _) => Some(k),
                (None, Some(_)) => None,
                (None, None) => self.certify_within,
            },
            max_validation: max_validation.unwrap_or(self.max_validation),
            ..self
        }
    }

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
        if let Some(k) = self.certify_within {
            if !(k.is_finite() && k > 1.0) {
                return invalid(
                    "certify_within",
                    k,
                    "a certified RMSE is never below the observed one; give a multiple above 1, \
                     such as 1.2",
                );
            }
            if self.max_validation < self.validation {
                return Err(Error::setting(
                    "max_validation",
                    self.max_validation.to_string(),
                    format!(
                        "below the first round of {} validation records",
                        self.validation
                    ),
                ));
            }
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
