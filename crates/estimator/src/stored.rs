//! The plain records an estimator stores about itself: what it was
//! trained on, the records it takes, and their signals' names. Both the
//! estimator and the file layouts read them, so they stand apart from
//! both.

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
    /// The design that placed the training parameters.
    pub sampling: String,
    /// The stage-2 method as configured.
    pub regressor: RegressorConfig,
    /// The twostage version that trained it.
    pub version: String,
}

/// The signals and sampling a record must have.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordShape {
    /// Samples per record the estimator was trained on.
    pub n_samples: usize,
    /// Input signals.
    pub n_inputs: usize,
    /// Output signals.
    pub n_outputs: usize,
    /// Sampling time.
    pub sample_time: f64,
}

/// The names of a model's input and output signals.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalNames {
    /// Input names, in the order of the record's input columns.
    pub inputs: Vec<String>,
    /// Output names.
    pub outputs: Vec<String>,
}
