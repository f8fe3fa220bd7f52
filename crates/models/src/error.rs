//! The one error type of this crate.

use thiserror::Error;
pub use twostage_setting::InvalidSetting;

/// Everything that can go wrong when describing or running a simulator.
///
/// Each variant carries the offending values and its message says what to do.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SimError {
    /// The simulation produced a non-finite state: the model diverged.
    #[error(
        "the simulation diverged (non-finite state) at t = {time} for theta = {theta:?}: \
         choose a parameter vector inside the model's stable region, or a smaller step"
    )]
    Diverged {
        /// The parameter vector that was simulated.
        theta: Vec<f64>,
        /// The time (in the model's time unit) of the first non-finite state.
        time: f64,
    },
    /// A state became NaN or infinite (a model written as equations).
    #[error(
        "the state {state} became {value} at t = {time} for theta = {theta:?}: the record \
         fails (counted in the failure allowance); check its equation there, or narrow the \
         prior to where the model is defined"
    )]
    NonFiniteState {
        /// The state's name.
        state: String,
        /// Its value (NaN or infinite).
        value: f64,
        /// The time of the first non-finite value.
        time: f64,
        /// The parameter vector that was simulated.
        theta: Vec<f64>,
    },
    /// A parameter vector of the wrong length was given.
    #[error("expected {expected} parameter values ({names}), got {got}")]
    WrongParameterCount {
        /// How many values the model takes.
        expected: usize,
        /// How many were given.
        got: usize,
        /// The model's parameter names, comma separated.
        names: String,
    },
    /// A parameter value lies outside the prior box.
    #[error(
        "parameter {name} = {value} lies outside the prior box [{lower}, {upper}]: \
         give a value inside it, or allow values outside the prior explicitly"
    )]
    OutsidePrior {
        /// The parameter's name.
        name: String,
        /// The value given.
        value: f64,
        /// Lower bound of the box.
        lower: f64,
        /// Upper bound of the box.
        upper: f64,
    },
    /// A parameter value is NaN or infinite.
    #[error("parameter {name} is not a finite number ({value})")]
    NonFiniteParameter {
        /// The parameter's name.
        name: String,
        /// The value given.
        value: f64,
    },
    /// A prior box was malformed.
    #[error("invalid prior box for parameter {index}: [{lower}, {upper}] ({reason})")]
    InvalidPrior {
        /// Index of the parameter.
        index: usize,
        /// The lower bound given.
        lower: f64,
        /// The upper bound given.
        upper: f64,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// A parameter's prior distribution was malformed.
    #[error("invalid prior for parameter {index}: {marginal} ({reason})")]
    InvalidMarginal {
        /// Index of the parameter.
        index: usize,
        /// The distribution as given.
        marginal: String,
        /// What is accepted.
        reason: &'static str,
    },
    /// An external simulator failed or broke the protocol.
    #[error("external simulator `{command}`: {message}")]
    External {
        /// The command line.
        command: String,
        /// What happened, quoting what it answered.
        message: String,
    },
    /// An FMU failed or was refused (the message names the FMU, the call
    /// and what the FMU logged).
    #[error("{0}")]
    Fmu(String),
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// No built-in model has this name.
    #[error("unknown model '{name}': the built-in models are {known}")]
    UnknownModel {
        /// The name given.
        name: String,
        /// The known names, comma separated.
        known: String,
    },
    /// Input/output data are malformed (lengths, shapes, non-finite samples).
    #[error("invalid data: {0}")]
    InvalidData(String),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, SimError>;
