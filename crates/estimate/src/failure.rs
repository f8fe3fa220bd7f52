//! Why a record (or a window of one) has no estimate.

use twostage_baselines::BaselineError;
use twostage_sources::csv_rows::DataFileError;

/// Why a record, or a window of one, has no estimate: each names the
/// record (its file and experiment, or its place in a batch).
///
/// ```
/// use twostage::RecordFailure;
/// let short = RecordFailure::ShorterThanWindow {
///     place: "runs.csv: experiment a".into(),
///     samples: 300,
///     window: 500,
/// };
/// assert_eq!(
///     short.to_string(),
///     "runs.csv: experiment a: 300 samples, shorter than the window of 500"
/// );
/// ```
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordFailure {
    /// The record could not be read from its file (the file, row and
    /// column say where).
    #[error(transparent)]
    Unreadable(#[from] DataFileError),
    /// The record is shorter than one window.
    #[error("{place}: {samples} samples, shorter than the window of {window}")]
    ShorterThanWindow {
        /// The record.
        place: String,
        /// Its samples.
        samples: usize,
        /// The window's length.
        window: usize,
    },
    /// The way of estimating refused the record or failed on it.
    #[error("{place}: {why}")]
    NotEstimated {
        /// The record.
        place: String,
        /// Why.
        why: MethodFailure,
    },
}

/// Why a way of estimating gave no estimate of a record it was handed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MethodFailure {
    /// A trained estimator refuses a record of another length than its
    /// training records' (it says which, and what to do).
    #[error("{0}")]
    Length(String),
    /// A trained estimator failed on the record.
    #[error(transparent)]
    Estimator(#[from] twostage_estimator::Error),
    /// A classic method, or the output-error fit, failed on the record.
    #[error(transparent)]
    Method(#[from] BaselineError),
    /// The output-error fit ended without a descent.
    #[error("the output-error fit made no descent: give it at least one start")]
    NoDescent,
    /// Given values do not fit the record.
    #[error(transparent)]
    Given(#[from] GivenValuesError),
    /// The draws could not be sharpened through the model (a run that
    /// failed, or a local likelihood that could not be fitted).
    #[error("the draws could not be sharpened through the model: {0}")]
    Sharpen(String),
}

/// Values given for records that do not fit them.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GivenValuesError {
    /// An experiment has two rows of values.
    #[error("{from}: experiment {id} has two rows of values: give one per experiment")]
    TwoRows {
        /// Where the values came from.
        from: String,
        /// The experiment.
        id: String,
    },
    /// A record's experiment has no row, among several.
    #[error(
        "{from} has no row for experiment {id}: give a row per experiment, or a single row for \
         every record"
    )]
    NoRow {
        /// Where the values came from.
        from: String,
        /// The experiment.
        id: String,
    },
}
