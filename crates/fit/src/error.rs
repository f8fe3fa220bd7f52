//! The one error type of this crate.

use thiserror::Error;
pub use twostage_setting::InvalidSetting;

/// Why a regressor could not be fitted or evaluated.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum FitError {
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// Features and targets disagree in shape, or a row has the wrong length.
    #[error("shape mismatch: {0}")]
    ShapeMismatch(String),
    /// Too few samples to fit.
    #[error("{got} training samples are too few: at least {needed} are needed ({why})")]
    TooFewSamples {
        /// Samples given.
        got: usize,
        /// Samples needed.
        needed: usize,
        /// Why.
        why: String,
    },
    /// A feature or target is NaN or infinite.
    #[error("{what} has a non-finite value ({value}) at row {row}, column {col}")]
    NonFinite {
        /// `features` or `targets`.
        what: &'static str,
        /// Row index.
        row: usize,
        /// Column index.
        col: usize,
        /// The value.
        value: f64,
    },
    /// The least-squares problem is rank deficient.
    #[error(
        "rank-deficient least squares: feature {feature} is a linear combination of the \
         others (or constant): use lambda > 0 or drop it"
    )]
    RankDeficient {
        /// The first dependent feature (0-based column).
        feature: usize,
    },
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, FitError>;
