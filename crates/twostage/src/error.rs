//! The one error type of the facade.

use thiserror::Error;
use twostage_compress::CompressError;
use twostage_fit::FitError;
use twostage_models::SimError;
use twostage_validate::ValidateError;

/// Everything that can go wrong while training, using or storing an estimator.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// A simulation failed or a model setting is wrong.
    #[error(transparent)]
    Simulation(#[from] SimError),
    /// A record could not be compressed.
    #[error(transparent)]
    Compression(#[from] CompressError),
    /// Stage 2 could not be fitted or evaluated.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// Validation failed.
    #[error(transparent)]
    Validation(#[from] ValidateError),
    /// Too many experiments of a chart failed.
    #[error(
        "{failed} of {total} {stage} experiments failed (at most {allowed} may): first, \
         experiment {first_index}: {first_error}"
    )]
    TooManyFailures {
        /// Which chart: training, calibration or validation.
        stage: &'static str,
        /// Failed experiments.
        failed: usize,
        /// All experiments.
        total: usize,
        /// The most that may fail.
        allowed: usize,
        /// Index of the first failure.
        first_index: usize,
        /// Its error.
        first_error: String,
    },
    /// A builder setting is out of range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidSetting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: String,
        /// The valid range.
        reason: String,
    },
    /// A record does not fit the estimator.
    #[error("the record does not fit this estimator: {0}")]
    Record(String),
    /// An estimator file could not be read or written.
    #[error("estimator file: {0}")]
    File(String),
    /// Reading or writing a file failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: String,
        /// What happened (not a `source`, so that error chains print it once).
        cause: std::io::Error,
    },
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, Error>;
