//! The one error type of this crate.

use thiserror::Error;
use twostage_compress::CompressError;
use twostage_fit::FitError;
use twostage_models::SimError;
pub use twostage_setting::InvalidSetting;

/// What can go wrong with a source of records: a model file, a chart on
/// disk, shards, or the simulations themselves.
///
/// [`Error::is_setting`] tells the mistakes in what the user wrote or
/// named from what went wrong while records were made.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// A simulation failed or a model setting is wrong.
    #[error(transparent)]
    Simulation(#[from] SimError),
    /// One experiment of a chart being written failed.
    #[error("simulating experiment {index}: {error}")]
    Experiment {
        /// Its index in the design.
        index: usize,
        /// What went wrong.
        error: SimError,
    },
    /// A record could not be compressed, or a stage-1 structure is wrong.
    #[error(transparent)]
    Compression(#[from] CompressError),
    /// A stage-2 structure is wrong.
    #[error(transparent)]
    Fit(#[from] FitError),
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
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// A model file is malformed.
    #[error(
        "{file}{}{}: {message}",
        line.map_or_else(String::new, |l| format!(", line {l}")),
        if key.is_empty() { String::new() } else { format!(", key `{key}`") }
    )]
    ModelFile {
        /// The file as it was named.
        file: String,
        /// The line of the mistake, when known.
        line: Option<usize>,
        /// The key, dotted from the table (`parameter.prior.sigma`).
        key: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// A chart file is malformed.
    #[error(
        "{file}{}: {message}",
        line.map_or_else(String::new, |l| format!(", line {l}"))
    )]
    ChartFile {
        /// The file.
        file: String,
        /// The line of the problem, when known.
        line: Option<usize>,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// Shards of a chart that are damaged, do not belong together, or
    /// leave records out.
    #[error("{what}: {message}")]
    Shards {
        /// The shard file or the pattern.
        what: String,
        /// What is wrong and what to do.
        message: String,
    },
    /// A model file has no preset of that name.
    #[error("{what} '{name}' is not available for {model}: it has {available}")]
    NotAvailable {
        /// "preset".
        what: &'static str,
        /// The name asked for.
        name: String,
        /// The model.
        model: String,
        /// What the model has instead.
        available: String,
    },
    /// The model given for an estimator's records is not the model it
    /// was trained on, or none was given for a model that is not built in.
    #[error(
        "{}: give the model file it was trained from",
        match given {
            Some((origin, name)) => format!(
                "{origin} describes '{name}', the estimator was trained on '{trained_on}'"
            ),
            None => format!("the estimator was trained on '{trained_on}', not a built-in model"),
        }
    )]
    OtherModel {
        /// The model the estimator was trained on.
        trained_on: String,
        /// Where the model given came from and the model it describes.
        given: Option<(String, String)>,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: String,
        /// What happened (not a `source`, so that error chains print it once).
        cause: std::io::Error,
    },
}

/// The result of this crate's fallible functions.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Whether the error is in what was asked for: a setting out of range,
    /// a structure that does not parse or fit the model, a preset the
    /// model lacks, a model file, chart or shard that is not what it
    /// should be, a model file of another model than the estimator's.
    ///
    /// ```
    /// use twostage_sources::Error;
    /// let e = Error::Shards { what: "runs/shard-*".into(), message: "none".into() };
    /// assert!(e.is_setting());
    /// ```
    pub fn is_setting(&self) -> bool {
        matches!(
            self,
            Self::InvalidSetting(_)
                | Self::NotAvailable { .. }
                | Self::ModelFile { .. }
                | Self::OtherModel { .. }
                | Self::ChartFile { .. }
                | Self::Shards { .. }
                | Self::Compression(CompressError::InvalidSetting(_))
                | Self::Fit(FitError::InvalidSetting(_))
        )
    }
}
