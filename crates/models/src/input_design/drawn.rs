//! A setting of an input design fixed, or drawn per experiment.

use rand::{Rng, RngExt};

use crate::InvalidSetting;
use crate::error::{Result, SimError};

/// A value fixed, or drawn uniformly per experiment from `[low, high]`.
///
/// ```
/// use twostage_models::Drawn;
/// assert_eq!(Drawn::fixed(2.0).range(), (2.0, 2.0));
/// assert!(Drawn::between(1.0, 0.5).is_err());
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drawn {
    low: f64,
    high: f64,
}

/// A number is the same value in every experiment.
impl From<f64> for Drawn {
    fn from(value: f64) -> Self {
        Self::fixed(value)
    }
}

impl Drawn {
    /// The same value in every experiment.
    pub fn fixed(value: f64) -> Self {
        Self {
            low: value,
            high: value,
        }
    }

    /// A value drawn uniformly from `[low, high]` per experiment.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for an empty or non-finite range.
    pub fn between(low: f64, high: f64) -> Result<Self> {
        if !(low.is_finite() && high.is_finite() && low <= high) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input range",
                value: format!("[{low}, {high}]"),
                reason: "give finite ends, the first no larger than the second".into(),
            }));
        }
        Ok(Self { low, high })
    }

    /// Its ends.
    pub fn range(&self) -> (f64, f64) {
        (self.low, self.high)
    }

    /// Whether it is one value, not a range.
    pub(crate) fn is_fixed(&self) -> bool {
        self.low.to_bits() == self.high.to_bits()
    }

    /// Refuses a range whose low end is below `least` (or at it, when
    /// `positive`), naming the setting and what is accepted.
    pub(crate) fn check_low(
        &self,
        name: &'static str,
        least: f64,
        positive: bool,
        reason: &str,
    ) -> Result<()> {
        let refused = if positive {
            self.low <= least
        } else {
            self.low < least
        };
        if refused {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name,
                value: self.low.to_string(),
                reason: reason.into(),
            }));
        }
        Ok(())
    }

    pub(crate) fn draw<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        if self.is_fixed() {
            self.low
        } else {
            self.low + (self.high - self.low) * rng.random::<f64>()
        }
    }

    pub(crate) fn describe(&self, unit: &str) -> String {
        if self.is_fixed() {
            format!("{}{unit}", self.low)
        } else {
            format!("{} to {}{unit} (drawn per experiment)", self.low, self.high)
        }
    }
}
