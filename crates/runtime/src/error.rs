//! Every way an estimate can fail, as a value (the runtime never panics).

/// Why a blob was refused or an estimate could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The blob does not start with `TSRT`: not an exported estimator.
    BadMagic,
    /// The blob's format version is one this build does not read.
    UnsupportedVersion {
        /// The version in the blob.
        found: u32,
    },
    /// The blob's declared length differs from the bytes given (a
    /// truncated copy, or one with bytes appended).
    Length {
        /// The length the header declares.
        declared: usize,
        /// The bytes given.
        actual: usize,
    },
    /// The checksum does not match: the blob was damaged.
    Checksum {
        /// The CRC-32 the header stores.
        stored: u32,
        /// The CRC-32 of the bytes.
        actual: u32,
    },
    /// A section runs past the blob's end.
    Truncated {
        /// Byte offset of the section.
        at: usize,
    },
    /// A value lies outside what it may be (a count beyond the runtime's
    /// limits, a non-finite weight, a box with lower >= upper, ...).
    Invalid {
        /// What the value is.
        field: &'static str,
        /// Byte offset where it was read.
        at: usize,
    },
    /// Bytes follow the last section.
    TrailingBytes {
        /// Byte offset of the first unread byte.
        at: usize,
    },
    /// The workspace given to a stream is smaller than
    /// [`crate::Estimator::workspace_len`].
    WorkspaceTooSmall {
        /// Words needed.
        needed: usize,
        /// Words given.
        given: usize,
    },
    /// A pushed sample has the wrong number of inputs or outputs, or a
    /// record's input and output arrays disagree.
    SignalCount {
        /// Inputs per sample the estimator takes.
        inputs: usize,
        /// Outputs per sample the estimator takes.
        outputs: usize,
    },
    /// A sample is NaN or infinite; the record cannot be estimated (reset
    /// the stream to start another).
    NotFinite {
        /// Index of the sample in the record.
        sample: usize,
    },
    /// The record is shorter than the regression needs.
    TooShort {
        /// Samples pushed.
        samples: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A regressor is (numerically) a combination of the ones before it:
    /// the input does not excite the system enough for these orders.
    RankDeficient {
        /// The output whose regression failed.
        output: usize,
        /// The regressor column.
        column: usize,
    },
    /// The sums left the floating-point range (samples near 1e150, or a
    /// linearized stage 1's model run that left its range on the record's
    /// input).
    Overflow,
    /// An output slice is shorter than the parameters.
    OutputTooShort {
        /// Numbers needed.
        needed: usize,
    },
    /// The workspace holds no stream: start one with `Stream::new`.
    NotStarted,
    /// A window shorter than one regression needs.
    WindowTooShort {
        /// The window asked for, in samples.
        window: usize,
        /// The fewest samples a window may hold.
        needed: usize,
    },
    /// The blob needs a part of the runtime that this build leaves out
    /// (a learned summary network without the feature `learned`, a
    /// linearized stage 1 without `linearized`, draws from its posterior
    /// without `posterior`).
    NotBuiltIn {
        /// The Cargo feature of `twostage-runtime` that builds it in.
        feature: &'static str,
    },
    /// Draws were asked of a blob without a posterior: train the
    /// estimator with one (`train --posterior K`) and export it again.
    NoPosterior,
    /// The draws' array is not a whole number of draws.
    DrawCount {
        /// Numbers per draw (the parameters).
        parameters: usize,
    },
}

impl Error {
    /// A stable number for C callers (always negative).
    pub fn code(&self) -> i32 {
        match self {
            Error::BadMagic => -1,
            Error::UnsupportedVersion { .. } => -2,
            Error::Length { .. } => -3,
            Error::Checksum { .. } => -4,
            Error::Truncated { .. } => -5,
            Error::Invalid { .. } => -6,
            Error::TrailingBytes { .. } => -7,
            Error::WorkspaceTooSmall { .. } => -8,
            Error::SignalCount { .. } => -9,
            Error::NotFinite { .. } => -10,
            Error::TooShort { .. } => -11,
            Error::RankDeficient { .. } => -12,
            Error::Overflow => -13,
            Error::OutputTooShort { .. } => -14,
            Error::NotStarted => -15,
            Error::WindowTooShort { .. } => -16,
            Error::NotBuiltIn { .. } => -17,
            Error::NoPosterior => -18,
            Error::DrawCount { .. } => -19,
        }
    }
}

impl Error {
    /// What a code of [`Error::code`] means, in one sentence without the
    /// details (a NUL-terminated string, for C callers); `None` for a code
    /// that is not one.
    pub fn explain(code: i32) -> Option<&'static core::ffi::CStr> {
        Some(match code {
            -1 => c"not an exported estimator (no TSRT magic): write one with twostage export --to runtime",
            -2 => c"the blob's format version is not the one this runtime reads: export it again",
            -3 => c"the blob's declared length differs from the bytes given (truncated or padded copy)",
            -4 => c"the blob's checksum does not match: it was damaged; export it again",
            -5 => c"a section of the blob runs past its end",
            -6 => c"a value in the blob is outside its range (a count beyond the runtime's limits, a non-finite weight)",
            -7 => c"bytes follow the blob's last section",
            -8 => c"the workspace is smaller than ts_workspace_len",
            -9 => c"a sample has the wrong number of inputs or outputs",
            -10 => c"a sample is not finite: the record cannot be estimated; reset the stream",
            -11 => c"too few samples for the regression or the summary network",
            -12 => c"a regressor is a combination of the others: the input does not excite the system enough",
            -13 => c"the sums overflowed: samples are far too large, or the model left its range on the record's input",
            -14 => c"the output array is shorter than the parameters",
            -15 => c"the workspace holds no stream: start one with ts_stream_start",
            -16 => c"the window is shorter than the regression or the summary network needs",
            -17 => c"the blob needs a part this runtime was built without: enable the runtime's feature that builds it (a learned summary: learned; a linearized stage 1: linearized; draws: posterior)",
            -18 => c"the blob carries no posterior to draw from: train the estimator with --posterior and export it again",
            -19 => c"the draws' array is not a whole number of draws (a multiple of the parameters)",
            _ => return None,
        })
    }
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Error::BadMagic => f.write_str(
                "not an exported estimator (no TSRT magic): write one with \
                 `twostage export --to runtime`",
            ),
            Error::UnsupportedVersion { found } => write!(
                f,
                "blob format version {found}, this runtime reads versions {} to {}: export \
                 the estimator again with the matching twostage",
                crate::format::VERSION_WITHOUT_FAMILY,
                crate::format::VERSION
            ),
            Error::Length { declared, actual } => write!(
                f,
                "the blob declares {declared} bytes but {actual} were given: the copy is \
                 truncated or padded"
            ),
            Error::Checksum { stored, actual } => write!(
                f,
                "checksum {actual:#010x} does not match the stored {stored:#010x}: the \
                 blob was damaged; export it again"
            ),
            Error::Truncated { at } => write!(f, "a section at byte {at} runs past the end"),
            Error::Invalid { field, at } => {
                write!(f, "invalid {field} at byte {at} of the blob")
            }
            Error::TrailingBytes { at } => write!(f, "unexpected bytes from byte {at} on"),
            Error::WorkspaceTooSmall { needed, given } => write!(
                f,
                "the workspace has {given} numbers, the estimator needs {needed} \
                 (Estimator::workspace_len)"
            ),
            Error::SignalCount { inputs, outputs } => write!(
                f,
                "a sample must have {inputs} input(s) and {outputs} output(s)"
            ),
            Error::NotFinite { sample } => write!(
                f,
                "sample {sample} is not finite: the record cannot be estimated; reset the \
                 stream"
            ),
            Error::TooShort { samples, needed } => write!(
                f,
                "{samples} samples pushed, the estimator needs at least {needed} (its regression and any summary network)"
            ),
            Error::RankDeficient { output, column } => write!(
                f,
                "regressor {column} of output {output} is (numerically) a combination of \
                 the ones before it: the input does not excite the system enough"
            ),
            Error::Overflow => f.write_str(
                "the sums overflowed: samples are far too large, or the model left its range on \
                 the record's input",
            ),
            Error::OutputTooShort { needed } => {
                write!(f, "an output slice needs room for {needed} numbers")
            }
            Error::NotStarted => {
                f.write_str("the workspace holds no stream: start one (Stream::new)")
            }
            Error::WindowTooShort { window, needed } => write!(
                f,
                "a window of {window} samples, the estimator needs at least {needed} (its \
                 regression and any summary network): take a longer window"
            ),
            Error::NotBuiltIn { feature } => write!(
                f,
                "the blob needs a part of the runtime that this build leaves out: \
                 build twostage-runtime with its feature `{feature}` (on by default)"
            ),
            Error::NoPosterior => f.write_str(
                "the blob carries no posterior to draw from: train the estimator with \
                 `--posterior K` and export it again",
            ),
            Error::DrawCount { parameters } => write!(
                f,
                "the draws' array must hold a whole number of draws of {parameters} \
                 parameters"
            ),
        }
    }
}

impl core::error::Error for Error {}
