//! The training side's one error, the facade's: the estimator's own
//! errors, and those of the record sources, the refinement and the
//! automatic design, which the trained estimator never meets.

use thiserror::Error;
use twostage_compress::CompressError;
use twostage_estimator::FileError;
use twostage_estimator::InvalidSetting;
use twostage_fit::FitError;
use twostage_models::SimError;
use twostage_refine::RefineError;
use twostage_sources::Error as SourceError;
use twostage_validate::ValidateError;

/// Everything that can go wrong while training, using or storing an
/// estimator (re-exported as `twostage::Error`).
///
/// [`Error::is_setting`] tells the mistakes a user fixes by changing what
/// they asked for (a setting, a structure, a file they named) from what
/// went wrong while the work ran.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// The estimator's own, or a stage it shares with training: its file,
    /// a record that does not fit it, a setting out of range, a simulation,
    /// compression, fit or validation that failed.
    #[error(transparent)]
    Estimator(#[from] twostage_estimator::Error),
    /// A source of records failed: a model file, a chart on disk, shards,
    /// or too many failed simulations.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// A refinement refused its settings or failed numerically.
    #[error(transparent)]
    Refine(#[from] RefineError),
    /// The automatic design went wrong inside, not in what was asked of
    /// it (the command line exits with 1, not 2).
    #[error("the automatic design failed: {what}")]
    Search {
        /// What went wrong.
        what: String,
    },
}

impl Error {
    /// A setting out of range: `name` = `value`, and `reason` says what is
    /// accepted (the estimator's [`twostage_estimator::Error::InvalidSetting`]).
    ///
    /// ```
    /// let e = twostage_train::Error::setting("sims", "0", "at least 1");
    /// assert_eq!(e.to_string(), "invalid sims = 0: at least 1");
    /// assert!(e.is_setting());
    /// ```
    pub fn setting(
        name: &'static str,
        value: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self::Estimator(twostage_estimator::Error::InvalidSetting(InvalidSetting {
            name,
            value: value.into(),
            reason: reason.into(),
        }))
    }

    /// Whether the error is in what was asked for: a setting out of range,
    /// a structure that does not parse or fit the model, a preset the model
    /// lacks, a model file, chart or shard that is not what it should be.
    /// The command line exits with 2 on these.
    ///
    /// ```
    /// use twostage::CompressorConfig;
    /// let e: twostage::Error = "arx:x".parse::<CompressorConfig>().unwrap_err().into();
    /// assert!(e.is_setting());
    /// ```
    pub fn is_setting(&self) -> bool {
        match self {
            Self::Estimator(e) => e.is_setting(),
            Self::Source(e) => e.is_setting(),
            Self::Refine(_) | Self::Search { .. } => false,
        }
    }
}

/// The stages' errors are the estimator's (it runs them too).
macro_rules! through_the_estimator {
    ($($stage:ty),*) => {$(
        impl From<$stage> for Error {
            fn from(error: $stage) -> Self {
                Self::Estimator(error.into())
            }
        }
    )*};
}
through_the_estimator!(SimError, CompressError, FitError, ValidateError, FileError);

/// The result of training and of the facade's fallible functions.
pub type Result<T> = std::result::Result<T, Error>;
