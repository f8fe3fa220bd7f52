//! What can go wrong with an estimator: its file, a record that does not
//! fit it, a stage that fails on a record. The training side's error
//! (`twostage_train::Error`, the facade's) wraps it.

use thiserror::Error;
use twostage_compress::CompressError;
use twostage_fit::FitError;
use twostage_models::SimError;
pub use twostage_setting::InvalidSetting;
use twostage_validate::ValidateError;

/// Everything that can go wrong while using or storing an estimator, and
/// in the stages a training run shares with it.
///
/// [`Error::is_setting`] tells the mistakes a user fixes by changing what
/// they asked for (a setting, a structure, a file they named) from what
/// went wrong while the work ran.
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
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// The estimator uses a structure the microcontroller runtime does not
    /// evaluate.
    #[error("this estimator cannot be exported to the runtime: {reason}")]
    NotExportable {
        /// What the runtime lacks and what to train instead.
        reason: String,
    },
    /// Draws were asked of an estimator trained without a conditional
    /// density.
    #[error(
        "this estimator has no posterior to draw from: train it with a density of the \
         parameters (`train --posterior`, `TwoStage::posterior`)"
    )]
    NoPosterior,
    /// A record or output slot does not fit the estimator.
    #[error(
        "the record does not fit this estimator: {what} has {found} values, the estimator \
         needs {expected}"
    )]
    Record {
        /// Which part: "theta" (the output slots), say.
        what: &'static str,
        /// What was given.
        found: usize,
        /// What the estimator needs.
        expected: usize,
    },
    /// An estimator file could not be read, decoded or written.
    #[error(
        "{}{error}",
        path.as_ref()
            .map_or_else(|| "estimator file: ".to_string(), |p| format!("{}: ", p.display()))
    )]
    File {
        /// The file, when one was named.
        path: Option<std::path::PathBuf>,
        /// What is wrong with it.
        error: FileError,
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

/// What is wrong with an estimator file's bytes: each case a variant, so
/// that a caller can tell a truncated, a newer and a damaged file apart.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum FileError {
    /// The bytes do not start with the magic `TWOSTAGE`.
    #[error(
        "not a twostage estimator file (it does not start with TWOSTAGE): give a file \
         written by `twostage train` or `Estimator::save`"
    )]
    BadMagic,
    /// Fewer bytes than the header or the payload needs.
    #[error("truncated: the {part} needs {expected} bytes, {found} are present")]
    Truncated {
        /// "header" or "payload".
        part: &'static str,
        /// Bytes needed.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// Bytes after the payload the header announced.
    #[error("{extra} unexpected bytes after the payload: the file is corrupted")]
    TrailingBytes {
        /// How many.
        extra: u64,
    },
    /// Written by a newer format version than this build reads.
    #[error(
        "written by a newer twostage (format version {found}; this build reads up to \
         {supported}): upgrade twostage to read it"
    )]
    NewerVersion {
        /// The file's version.
        found: u32,
        /// The newest this build reads.
        supported: u32,
    },
    /// A version number that no build ever wrote.
    #[error("format version {found} does not exist: the file is corrupted")]
    UnknownVersion {
        /// The file's version.
        found: u32,
    },
    /// The payload's checksum does not match the header's.
    #[error("corrupted: checksum {actual:08x} does not match the stored {stored:08x}")]
    BadChecksum {
        /// The header's CRC-32.
        stored: u32,
        /// The payload's.
        actual: u32,
    },
    /// The payload is not a postcard-encoded estimator.
    #[error("the payload does not decode ({reason}): the file is corrupted")]
    Undecodable {
        /// The decoder's message.
        reason: String,
    },
    /// The parts decode but do not agree with each other (sizes, ranges).
    #[error("inconsistent estimator: {what}")]
    Inconsistent {
        /// Which parts disagree, with their sizes or values.
        what: String,
    },
    /// Encoding (postcard or JSON) failed.
    #[error("encoding the estimator failed: {reason}")]
    Encoding {
        /// The encoder's message.
        reason: String,
    },
}

impl From<FileError> for Error {
    fn from(error: FileError) -> Self {
        Error::File { path: None, error }
    }
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Whether the error is in what was asked for: a setting out of range,
    /// a structure that does not parse or fit the model. The command line
    /// exits with 2 on these.
    ///
    /// ```
    /// use twostage::CompressorConfig;
    /// use twostage::estimator::Error;
    /// let e: Error = "arx:x".parse::<CompressorConfig>().unwrap_err().into();
    /// assert!(e.is_setting());
    /// ```
    pub fn is_setting(&self) -> bool {
        matches!(
            self,
            Self::InvalidSetting(_)
                | Self::Compression(CompressError::InvalidSetting(_))
                | Self::Fit(FitError::InvalidSetting(_))
                | Self::Validation(ValidateError::InvalidSetting(_))
        )
    }
}
