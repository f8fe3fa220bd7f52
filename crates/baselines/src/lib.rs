//! The paper's competitors to the two-stage estimator.
//!
//! Every method estimates theta from one record behind one trait,
//! [`RecordEstimator`]. This crate knows the models, never the two-stage
//! pipeline, so the comparison is fair by construction.
//!
//! It starts with the exact likelihood of the benchmark: given theta the
//! benchmark is linear and Gaussian, so [`benchmark_kalman`] gives the
//! optimal one-step predictor and the exact log-likelihood, on which the
//! prediction-error method and the Bayes-optimal reference rest.
//!
//! # Example
//!
//! ```
//! use twostage_baselines::benchmark_kalman;
//! use twostage_models::{experiment_rng, Benchmark, Simulator};
//!
//! let model = Benchmark::new();
//! let mut record = model.spec().new_record();
//! model.simulate(&[-0.3], &mut experiment_rng(1, 0), &mut record)?;
//! // The log-likelihood on a grid peaks near the truth.
//! let best = (-90..=90)
//!     .map(|i| i as f64 / 100.0)
//!     .max_by(|a, b| {
//!         let la = benchmark_kalman(*a, &record).unwrap().log_likelihood;
//!         let lb = benchmark_kalman(*b, &record).unwrap().log_likelihood;
//!         la.total_cmp(&lb)
//!     })
//!     .unwrap();
//! assert!((best + 0.3).abs() < 0.05);
//! # Ok::<(), twostage_baselines::BaselineError>(())
//! ```
#![deny(missing_docs)]

mod augmented;
mod bayes;
mod car;
mod error;
mod filters;
mod indirect;
mod kalman;
mod particle;
mod pem;
mod suite;

pub use augmented::{
    InitialCovariance, THETA_RANDOM_WALK_VARIANCE, transition, transition_jacobian,
};
pub use bayes::{BayesBenchmark, Posterior};
pub use car::{BayesCar, CarParticles, CarPosterior, CarPredictor};
pub use error::{BaselineError, InvalidSetting, Result};
pub use filters::{FilterRun, FilterStart, KalmanEstimator, UnscentedParams, run_ekf, run_ukf};
pub use indirect::{
    COMMON_NUMBERS_SEED, IndirectInference, IndirectObjective, WEIGHTING_SEED, Weighting,
};
pub use kalman::{BenchmarkStateSpace, KalmanRun, benchmark_kalman, benchmark_kalman_innovations};
pub use particle::{BenchmarkParticles, ParticleFilter, ParticleModel};
pub use pem::{BenchmarkPredictor, PredictionError};
pub use suite::{MethodSettings, classic_estimator, exact_likelihood};
pub use twostage_fit::TerminationReason;

use twostage_models::IoData;

/// An estimate of theta from one record, with a spread where the method gives one.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// The estimate.
    pub theta: Vec<f64>,
    /// Standard deviation per parameter (filters' covariances, posterior
    /// spreads), when the method provides one.
    pub spread: Option<Vec<f64>>,
}

/// A method that estimates theta from one input/output record.
pub trait RecordEstimator: Send + Sync {
    /// A short name for tables, e.g. `ekf` or `pem5`.
    fn name(&self) -> &str;

    /// Estimate theta from `record`.
    ///
    /// # Errors
    /// A record the method cannot use, or a numerical failure.
    fn estimate(&self, record: &IoData) -> Result<Estimate>;
}
