//! The one error type of this crate.

use thiserror::Error;
pub use twostage_setting::InvalidSetting;

/// Why a record could not be compressed.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CompressError {
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// The record's signals do not have the shape the compressor was built for.
    #[error(
        "the record has {got_inputs} input and {got_outputs} output signals, \
         the compressor expects {inputs} and {outputs}"
    )]
    ShapeMismatch {
        /// Inputs expected.
        inputs: usize,
        /// Outputs expected.
        outputs: usize,
        /// Inputs given.
        got_inputs: usize,
        /// Outputs given.
        got_outputs: usize,
    },
    /// Inputs and outputs have different lengths.
    #[error("the inputs have {inputs} samples but the outputs have {outputs}")]
    LengthMismatch {
        /// Input samples.
        inputs: usize,
        /// Output samples.
        outputs: usize,
    },
    /// A sample is NaN or infinite.
    #[error("{signal} has a non-finite value ({value}) at sample {index}: repair or drop it")]
    NonFinite {
        /// Which signal, e.g. `y` or `u2`.
        signal: String,
        /// The sample index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Too few samples for the chosen orders.
    #[error(
        "the record has {n_samples} samples, too short for {structure}: it needs at \
         least {needed}; use a longer record or lower orders"
    )]
    RecordTooShort {
        /// Samples given.
        n_samples: usize,
        /// Samples needed.
        needed: usize,
        /// The structure, e.g. `ARX(5, 5)`.
        structure: String,
    },
    /// The regressors are (numerically) rank deficient.
    #[error("rank-deficient regressors for {structure}: {cause}")]
    RankDeficient {
        /// The structure, e.g. `ARX(5, 5)`.
        structure: String,
        /// What makes them so, and what to do.
        cause: String,
    },
    /// The structure works on records of one fixed length only.
    #[error(
        "the record has {got} samples, but {structure} was fitted on records of exactly \
         {expected}: record with the training length"
    )]
    FixedLength {
        /// Samples of the training records.
        expected: usize,
        /// Samples given.
        got: usize,
        /// The structure, e.g. `PCA(20)`.
        structure: String,
    },
    /// A sample lies outside the domain of its output's transform.
    #[error(
        "{signal} is {value} at sample {index}: its transform {transform} takes {domain}; train \
         with another transform (id, or log1p for signals that reach zero), or repair the sample"
    )]
    OutsideTransform {
        /// Which signal, e.g. `y2`.
        signal: String,
        /// The sample index.
        index: usize,
        /// The value.
        value: f64,
        /// The transform, e.g. `log`.
        transform: &'static str,
        /// What the transform takes.
        domain: &'static str,
    },
    /// The output buffer has the wrong length.
    #[error("the feature buffer has {got} slots, the compressor produces {expected}")]
    BufferLength {
        /// Features produced.
        expected: usize,
        /// Slots given.
        got: usize,
    },
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, CompressError>;
