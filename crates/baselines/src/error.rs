//! The one error type of this crate.

use thiserror::Error;
use twostage_models::SimError;

/// Why a baseline could not produce an estimate.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum BaselineError {
    /// The model rejected the parameter vector or the data.
    #[error(transparent)]
    Model(#[from] SimError),
    /// A record could not be compressed (indirect inference).
    #[error(transparent)]
    Compress(#[from] twostage_compress::CompressError),
    /// A setting of the method is out of range.
    #[error("invalid setting: {0}")]
    InvalidSetting(String),
    /// The record does not suit the method.
    #[error("invalid record: {0}")]
    InvalidRecord(String),
    /// The filter's covariance lost positive definiteness.
    #[error("numerical failure at sample {sample}: {what}")]
    Numerical {
        /// The sample at which it happened.
        sample: usize,
        /// What happened.
        what: String,
    },
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, BaselineError>;
