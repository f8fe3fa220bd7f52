//! The one error type of this crate.

use thiserror::Error;
pub use twostage_setting::InvalidSetting;

/// What a refinement refuses or cannot compute; a [`ResidualModel`]'s own
/// error converts from it.
///
/// [`ResidualModel`]: crate::ResidualModel
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum RefineError {
    /// A setting is out of its valid range.
    #[error(transparent)]
    InvalidSetting(#[from] InvalidSetting),
    /// A vector given with a record (a start, a radius) has the wrong length.
    #[error("{what} has {found} values where {expected} are needed, one per parameter")]
    Length {
        /// Which vector.
        what: &'static str,
        /// Its length.
        found: usize,
        /// The number of parameters.
        expected: usize,
    },
    /// Simulating the model at the estimate failed.
    #[error("{what}: {source}")]
    Simulation {
        /// Which run failed.
        what: &'static str,
        /// What the simulator said.
        source: twostage_models::SimError,
    },
    /// A computation on a record gave no finite answer.
    #[error("numerical failure: {what}")]
    Numerical {
        /// What failed, and where.
        what: String,
    },
}
