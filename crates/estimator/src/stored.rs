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
    /// Where the training records came from, as
    /// [`twostage_models::RecordsOrigin::line`] writes it (the design that
    /// drew their parameters, or the chart they were read from):
    /// [`TrainingInfo::records`] reads it.
    pub sampling: String,
    /// The stage-2 method as configured.
    pub regressor: RegressorConfig,
    /// The twostage version that trained it.
    pub version: String,
}

impl TrainingInfo {
    /// Where the training records came from.
    ///
    /// ```
    /// use twostage_estimator::TrainingInfo;
    /// use twostage_models::{RecordsOrigin, Sampling};
    /// let info = TrainingInfo {
    ///     model: "benchmark".into(),
    ///     simulations: 300,
    ///     failures: 0,
    ///     seed: 1,
    ///     sampling: RecordsOrigin::Drawn(Sampling::LatinHypercube).line(),
    ///     regressor: "linear".parse().unwrap(),
    ///     version: "0.1.0".into(),
    /// };
    /// assert_eq!(info.records(), RecordsOrigin::Drawn(Sampling::LatinHypercube));
    /// ```
    pub fn records(&self) -> twostage_models::RecordsOrigin<'_> {
        twostage_models::RecordsOrigin::read(&self.sampling)
    }
}

/// The names of a model's input and output signals.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalNames {
    /// Input names, in the order of the record's input columns.
    pub inputs: Vec<String>,
    /// Output names.
    pub outputs: Vec<String>,
}
