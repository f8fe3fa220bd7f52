//! Stage 2 of the two-stage estimator: fitting.
//!
//! Given the compressed chart `{theta_i, alpha_i}`, stage 2 fits a map
//! `h: alpha -> theta` minimising the mean squared error, eq. (3) of the
//! paper. Features and targets are standardized on the training data and the
//! standardization is stored with the model.
//!
//! - [`Ridge`] -> [`FittedLinear`]: linear (ridge) least squares by QR.
//! - [`MlpParams`] -> [`Mlp`] -> [`FittedMlp`]: tanh networks trained by
//!   Levenberg-Marquardt, with early stopping and parallel seeded restarts.
//! - [`MixtureDensity`] -> [`FittedMixture`]: a conditional density of the
//!   parameters (a mixture of Gaussians a tanh network gives), trained by
//!   negative log-likelihood, to evaluate and draw from.
//! - [`Standardizer`]: per-column affine standardization.
//! - [`SummaryTraining`] -> [`twostage_compress::SummaryNetwork`]: a stage 1 that learns, a
//!   small convolutional network over a record's samples trained end to
//!   end with a head on the parameters, whose summary stage 2 then fits.
//!
//! # Example
//!
//! ```
//! use ndarray::Array2;
//! use twostage_fit::{Predictor, Regressor, Ridge};
//!
//! let x = Array2::from_shape_fn((50, 3), |(i, j)| ((i * 31 + j * 17) % 11) as f64);
//! let y = Array2::from_shape_fn((50, 1), |(i, _)| x[[i, 0]] - 0.5 * x[[i, 2]]);
//! let model = Ridge::default().fit(x.view(), y.view())?;
//! let prediction = model.predict(x.view())?;
//! assert!((prediction[[7, 0]] - y[[7, 0]]).abs() < 1e-6);
//! # Ok::<(), twostage_fit::FitError>(())
//! ```
#![deny(missing_docs)]

mod adam;
mod check;
mod config;
mod covariance;
mod error;
mod levenberg_marquardt;
mod linear;
mod mlp;
mod piecewise;
mod standardize;
mod summary_network;

use ndarray::{Array2, ArrayView2};

pub use config::{FittedRegressor, RegressorConfig};
pub use covariance::CovarianceFactor;
pub use error::{FitError, InvalidSetting, Result};
pub use levenberg_marquardt::{
    CentralDifferences, Damping, Evaluation, ForwardDifferences, Iterate, LeastSquaresProblem,
    LevenbergMarquardt, LmRun, Minimum, ModelAt, Need, TerminationReason, normal_products,
};
pub use linear::{FittedLinear, Ridge};
pub use mlp::{
    Classifier, DensityRestart, FittedClassifier, FittedMixture, FittedMlp, MAX_WIDTH,
    MixtureDensity, Mlp, MlpParams, RestartReport, Trainer, n_parameters, products_per_sample,
    two_sample_accuracy,
};
pub use piecewise::{FittedPiecewise, Piecewise};
pub use standardize::Standardizer;
pub use summary_network::{SummaryTraining, TrainedSummary};
pub use twostage_kernels::mixture::{MixtureShape, Support};

/// A learning method for the map `h: alpha -> theta` (its hyperparameters).
pub trait Regressor {
    /// The fitted model.
    type Model: Predictor;

    /// Fit on `x` (samples x features) and `y` (samples x targets).
    ///
    /// # Errors
    /// Mismatched shapes, non-finite values, too few samples, or a
    /// degenerate problem.
    fn fit(&self, x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<Self::Model>;
}

/// A fitted map from features to targets.
pub trait Predictor: Send + Sync {
    /// Number of features.
    fn n_inputs(&self) -> usize;
    /// Number of targets.
    fn n_outputs(&self) -> usize;

    /// Predict the targets of one feature vector into `out`, allocation-free.
    ///
    /// # Errors
    /// [`FitError::ShapeMismatch`] if a slice has the wrong length.
    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()>;

    /// Predict every row of `x`.
    ///
    /// # Errors
    /// [`FitError::ShapeMismatch`] if `x` has the wrong number of columns.
    fn predict(&self, x: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
        let mut out = Array2::zeros((x.nrows(), self.n_outputs()));
        let mut row = vec![0.0; x.ncols()];
        for (xi, mut oi) in x.rows().into_iter().zip(out.rows_mut()) {
            for (r, v) in row.iter_mut().zip(xi.iter()) {
                *r = *v;
            }
            let o = oi
                .as_slice_mut()
                .ok_or_else(|| FitError::ShapeMismatch("non-contiguous output".into()))?;
            self.predict_into(&row, o)?;
        }
        Ok(out)
    }
}
