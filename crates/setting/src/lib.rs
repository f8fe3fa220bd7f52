//! A setting out of its range, said the same way by every crate.
//!
//! Compressors, fitters, simulators, sources, refinements, validation and
//! the competitors all take settings from the user (an order, a width, a
//! confidence, a number of simulations), and each refuses a value out of
//! range before any work starts. They refuse it with this one type, so that
//! a caller tells the user's mistake from a failure of the work by one
//! match, whichever crate refused, and every refusal reads alike:
//! `invalid <setting> = <value>: <what is accepted>`.
//!
//! Each crate's error enum holds it as its `InvalidSetting` variant:
//!
//! ```
//! use twostage_setting::InvalidSetting;
//!
//! #[derive(Debug, thiserror::Error)]
//! enum FilterError {
//!     #[error(transparent)]
//!     InvalidSetting(#[from] InvalidSetting),
//! }
//!
//! fn filter_order(order: usize) -> Result<usize, FilterError> {
//!     if !(1..=8).contains(&order) {
//!         return Err(InvalidSetting::new("order", order, "1 to 8").into());
//!     }
//!     Ok(order)
//! }
//!
//! let refused = filter_order(12).unwrap_err();
//! assert_eq!(refused.to_string(), "invalid order = 12: 1 to 8");
//! let FilterError::InvalidSetting(setting) = refused;
//! assert_eq!(setting.name, "order");
//! ```

use std::fmt::Display;

use thiserror::Error;

/// A setting the user gave that is out of its valid range.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("invalid {name} = {value}: {reason}")]
pub struct InvalidSetting {
    /// The setting, as the user names it (a key, a flag's word).
    pub name: &'static str,
    /// The value given, as text.
    pub value: String,
    /// What is accepted, or what to do instead.
    pub reason: String,
}

impl InvalidSetting {
    /// The refusal of `value` for the setting `name`, with what is accepted.
    ///
    /// ```
    /// let refused = twostage_setting::InvalidSetting::new("delta", 1.5, "between 0 and 1");
    /// assert_eq!(refused.value, "1.5");
    /// ```
    pub fn new(name: &'static str, value: impl Display, reason: impl Into<String>) -> Self {
        Self {
            name,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}
