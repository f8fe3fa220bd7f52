//! The one error type of this crate.

use thiserror::Error;

/// Everything that can go wrong with an FMU, each naming the FMU and what
/// to do.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum FmiError {
    /// The file could not be read.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        message: String,
    },
    /// The file is not a zip archive (an FMU is one).
    #[error(
        "{path} is not an FMU: {message}; an FMU is a zip archive holding \
         modelDescription.xml and binaries/ (export one from your modelling tool)"
    )]
    NotAnArchive {
        /// The file.
        path: String,
        /// What is wrong with it.
        message: String,
    },
    /// Unpacking the archive would take more room than its disk has.
    #[error("{path} cannot be unpacked here: {message}")]
    NoRoom {
        /// The FMU.
        path: String,
        /// What it would take and what there is.
        message: String,
    },
    /// `modelDescription.xml` is missing or malformed.
    #[error("{path}, modelDescription.xml{}: {message}", line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Description {
        /// The FMU.
        path: String,
        /// The line of modelDescription.xml, where one is to blame.
        line: Option<usize>,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// The FMU is of an FMI version this crate does not run.
    #[error(
        "{path} is an FMI {version} FMU: twostage runs FMI 2.0 and 3.0 \
         (export the model again as FMI 2.0 or 3.0)"
    )]
    UnsupportedVersion {
        /// The FMU.
        path: String,
        /// The version it declares.
        version: String,
    },
    /// The FMU holds no binary for this platform.
    #[error(
        "{path} has no binary for this platform: expected {expected}, found {found}; \
         export the FMU for this platform (or with its C sources and compile them)"
    )]
    NoBinary {
        /// The FMU.
        path: String,
        /// The file looked for.
        expected: String,
        /// The platforms it has.
        found: String,
    },
    /// The binary could not be loaded or lacks a function.
    #[error("{path}: the binary {binary} {message}")]
    Binary {
        /// The FMU.
        path: String,
        /// The shared library.
        binary: String,
        /// What failed.
        message: String,
    },
    /// A name does not fit the role the model file gives it.
    #[error("{path}: variable '{name}': {message}")]
    Variable {
        /// The FMU.
        path: String,
        /// The variable name as given.
        name: String,
        /// What is wrong and what would work.
        message: String,
    },
    /// The FMU cannot be simulated the way asked.
    #[error("{path}: {message}")]
    Interface {
        /// The FMU.
        path: String,
        /// What is missing or refused, and what to do.
        message: String,
    },
    /// A call into the FMU returned an error (or was refused).
    #[error("{path}: {function} at t = {time} returned {status}{}", log_tail(log))]
    Call {
        /// The FMU.
        path: String,
        /// The FMI function.
        function: &'static str,
        /// The simulation time of the call.
        time: f64,
        /// The status it returned, in the standard's words.
        status: String,
        /// The last messages the FMU logged.
        log: Vec<String>,
    },
    /// A worker process (for an FMU that allows one instance per process)
    /// failed or ended.
    #[error("{path}: worker process: {message}")]
    Worker {
        /// The FMU.
        path: String,
        /// What happened.
        message: String,
    },
    /// A setting is out of its valid range.
    #[error("invalid FMU setting {name} = {value}: {reason}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value, as text.
        value: String,
        /// What is accepted.
        reason: String,
    },
}

fn log_tail(log: &[String]) -> String {
    if log.is_empty() {
        "; the FMU logged nothing".into()
    } else {
        format!("; the FMU logged: {}", log.join(" | "))
    }
}

impl From<FmiError> for twostage_models::SimError {
    fn from(e: FmiError) -> Self {
        twostage_models::SimError::Fmu(e.to_string())
    }
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, FmiError>;
