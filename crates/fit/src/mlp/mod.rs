//! Small feed-forward networks (tanh hidden layers, linear outputs) trained
//! by Levenberg-Marquardt with a held-out split for early stopping and
//! seeded restarts run in parallel.
//!
//! - `params`: the hyperparameters, unchecked and checked;
//! - `network`: the forward pass, back-propagation and the fitted network;
//! - `training`: restarts, the Levenberg-Marquardt and Adam trainers;
//! - `lbfgs`: the L-BFGS trainer, for many rows and weights;
//! - `held_out`: a restart's held-out watch, shared by the trainers.

mod classifier;
mod density;
mod gauss_newton;
mod held_out;
mod lbfgs;
mod likelihood;
mod network;
mod params;
mod stored;
mod training;

pub use classifier::{Classifier, FittedClassifier, two_sample_accuracy};
pub use density::{FittedMixture, MixtureDensity};
pub use gauss_newton::products_per_sample;
pub(crate) use held_out::BestHeldOut;
pub use likelihood::DensityRestart;
pub use network::RestartReport;
pub use network::{FittedMlp, MAX_WIDTH, n_parameters};
pub(crate) use params::DEFAULT_RESTARTS;
pub use params::{Mlp, MlpParams, Trainer};
