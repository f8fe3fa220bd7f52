//! The one error type of this crate.

use thiserror::Error;
use twostage_models::SimError;
pub use twostage_setting::InvalidSetting;

/// Why a baseline could not produce an estimate.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BaselineError {
    /// The model rejected the parameter vector or the data.
    #[error(transparent)]
    Model(#[from] SimError),
    /// A record could not be compressed (indirect inference).
    #[error(transparent)]
    Compress(#[from] twostage_compress::CompressError),
    /// The refinement's descent (on which prediction error and indirect
    /// inference descend) refused a setting or failed.
    #[error(transparent)]
    Refine(#[from] twostage_refine::RefineError),
    /// The model's table entry does not list the method.
    #[error("method '{method}' is not available for {model}: it has {available}")]
    NotAvailable {
        /// The method asked for.
        method: &'static str,
        /// The model.
        model: &'static str,
        /// The methods the model has.
        available: String,
    },
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// A record, or a buffer or vector given with it, has the wrong shape.
    #[error("{what}: {found}, where the method needs {expected}")]
    Shape {
        /// What has the wrong shape.
        what: &'static str,
        /// What was given.
        found: String,
        /// What the method needs.
        expected: String,
    },
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
