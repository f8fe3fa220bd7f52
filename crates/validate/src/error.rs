//! The one error type of this crate.

use thiserror::Error;
pub use twostage_setting::InvalidSetting;

/// What can be wrong with a validation request.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ValidateError {
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// An observed squared error exceeds the bound sigma the theorem assumes.
    #[error(
        "validation error {index} is {value}, above the assumed bound sigma = {sigma}: \
         clip estimates to the prior box, or pass the right sigma"
    )]
    AboveSigma {
        /// Which validation experiment.
        index: usize,
        /// Its squared error.
        value: f64,
        /// The assumed bound.
        sigma: f64,
    },
    /// No validation errors were given, or one was NaN or infinite.
    #[error("invalid validation errors: {0}")]
    InvalidErrors(String),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, ValidateError>;
