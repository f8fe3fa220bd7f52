//! Stage 1 of the two-stage estimator: compression.
//!
//! The first stage maps a long input/output record `D^N` to a short vector
//! of "compressed artificial data" `alpha` in `R^n`, `n << N` (Section 3.2
//! of the paper): the least-squares coefficients of a simple black-box
//! model fitted to the record. The model has no physical meaning; what
//! matters is that its coefficients move with the unknown parameters.
//!
//! - [`Arx`]: ARX(na, nb) by least squares, the paper's eq. (2), solved by
//!   Householder QR (faer) with an explicit rank check.
//! - [`Narx`]: polynomial NARX (all monomials up to a degree, or pure
//!   powers) on scaled signals, for strongly nonlinear systems.
//! - [`OutputPca`]: the leading principal components of the output record,
//!   for experiments that all apply the same input.
//! - [`Transformed`]: logarithms (or `ln(1 + y)`) of the outputs before
//!   any of the above, for signals that span decades.
//! - [`Workspace`]: scratch space so that compressing record after record
//!   allocates nothing.
//!
//! # Example
//!
//! ```
//! use ndarray::Array2;
//! use twostage_compress::{Arx, Compressor, Workspace};
//!
//! // y(t) = 0.8 y(t-1) - 0.15 y(t-2) + 1.0 u(t-1) + 0.5 u(t-2), noise-free.
//! let n = 200;
//! let u = Array2::from_shape_fn((n, 1), |(k, _)| ((k * 7919) % 13) as f64 / 6.0 - 1.0);
//! let mut y = Array2::<f64>::zeros((n, 1));
//! for t in 2..n {
//!     y[[t, 0]] = 0.8 * y[[t - 1, 0]] - 0.15 * y[[t - 2, 0]] + u[[t - 1, 0]] + 0.5 * u[[t - 2, 0]];
//! }
//! let alpha = Arx::new(2, 2)?.compress(u.view(), y.view())?;
//! for (got, want) in alpha.iter().zip([0.8, -0.15, 1.0, 0.5]) {
//!     assert!((got - want).abs() < 1e-10);
//! }
//! # Ok::<(), twostage_compress::CompressError>(())
//! ```
#![deny(missing_docs)]

mod arx;
mod config;
mod error;
mod fast;
mod linearized;
mod narx;
mod pca;
mod raw;
mod signals;
mod workspace;

use ndarray::ArrayView2;

pub use arx::Arx;
pub use config::{
    CompressorConfig, ConvShape, LearnedShape, NARX_SCALE_RECORDS, PCA_RECORDS, SignalTransform,
    SummaryNetwork, TRANSFORM_RECORDS, Transformed, WithLearned, WithLevel, WithSummary,
};
pub use error::{CompressError, InvalidSetting, Result};
pub use linearized::{DEFAULT_SUBSTEPS, Linearized, MAX_SUBSTEPS};
pub use narx::{Narx, signal_rms};
pub use pca::OutputPca;
pub use raw::{MAX_RAW_FEATURES, RawRecord};
pub use workspace::{FlooredSample, RANK_TOLERANCE, Workspace};

/// The compression map g: a record `(u, y)` to features `alpha` in `R^n`.
///
/// `inputs` is `N x n_u` and `outputs` is `N x n_y`, one signal per column.
pub trait Compressor: Send + Sync {
    /// The number n of features produced.
    fn n_features(&self) -> usize;

    /// Compress one record into `alpha` (of length [`Compressor::n_features`]),
    /// using `work` as scratch space: the hot path, allocation-free once
    /// `work` has seen a record of this size.
    ///
    /// # Errors
    /// Shapes that do not match the compressor, non-finite samples, a record
    /// too short for the structure, or rank-deficient regressors.
    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()>;

    /// The same features as [`Compressor::compress_into`], computed by the
    /// fastest method the compressor has, to agree with it to 1e-9
    /// relative: the path of estimates. Defaults to `compress_into`.
    ///
    /// # Errors
    /// As [`Compressor::compress_into`].
    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.compress_into(inputs, outputs, work, alpha)
    }

    /// Names of the features, for reports.
    fn feature_names(&self) -> Vec<String> {
        (1..=self.n_features())
            .map(|k| format!("alpha{k}"))
            .collect()
    }

    /// Compress one record into a new vector (allocates a workspace).
    ///
    /// # Errors
    /// As [`Compressor::compress_into`].
    fn compress(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
    ) -> Result<Vec<f64>> {
        let mut alpha = vec![0.0; self.n_features()];
        self.compress_into(inputs, outputs, &mut Workspace::new(), &mut alpha)?;
        Ok(alpha)
    }
}
