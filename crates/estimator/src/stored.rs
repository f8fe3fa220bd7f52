//! The plain records an estimator stores about itself: what it was
//! trained on and its signals' names (the records it takes are a
//! [`twostage_models::RecordShape`]). Both the estimator and the file
//! layouts read them, so they stand apart from both.

use serde::{Deserialize, Serialize};
use twostage_fit::RegressorConfig;

/// What the estimator was trained on, for people and for audits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingInfo {
    /// The model's name.
    pub model: String,
    /// Number of training simulations m.
    pub simulations: usize,
    /// Simulations that failed and were dropped.
    pub failures: usize,
    /// The training seed.
    pub seed: u64,
    /// The design that placed the training parameters (its name, as
    /// [`twostage_models::Sampling::name`] writes it), or the chart the
    /// records were read from (`twostage::sources::chart_of` tells them apart).
    pub sampling: String,
    /// The stage-2 method as configured.
    pub regressor: RegressorConfig,
    /// The twostage version that trained it.
    pub version: String,
}

/// The names of a model's input and output signals.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalNames {
    /// Input names, in the order of the record's input columns.
    pub inputs: Vec<String>,
    /// Output names.
    pub outputs: Vec<String>,
}
