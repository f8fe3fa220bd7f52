//! The stage-1 and stage-2 choices, as serializable values.

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
use twostage_compress::{Arx, Compressor, Narx, OutputPca, Workspace};
use twostage_fit::{
    FittedLinear, FittedMlp, FittedPiecewise, Mlp, Piecewise, Predictor, Regressor, Ridge,
};

/// The compression map g of stage 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum CompressorConfig {
    /// ARX(na, nb) least-squares coefficients, eq. (2).
    Arx(Arx),
    /// Polynomial NARX coefficients on scaled signals.
    Narx(Narx),
    /// Leading principal components of the output record (for models whose
    /// experiments all apply one input); fitted from the training design.
    Pca(OutputPca),
}

impl std::fmt::Display for CompressorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Arx(arx) => arx.fmt(f),
            Self::Narx(narx) => narx.fmt(f),
            Self::Pca(pca) => pca.fmt(f),
        }
    }
}

impl From<Arx> for CompressorConfig {
    fn from(arx: Arx) -> Self {
        Self::Arx(arx)
    }
}

impl From<Narx> for CompressorConfig {
    fn from(narx: Narx) -> Self {
        Self::Narx(narx)
    }
}

impl From<OutputPca> for CompressorConfig {
    fn from(pca: OutputPca) -> Self {
        Self::Pca(pca)
    }
}

impl Compressor for CompressorConfig {
    fn n_features(&self) -> usize {
        match self {
            Self::Arx(c) => c.n_features(),
            Self::Narx(c) => c.n_features(),
            Self::Pca(c) => c.n_features(),
        }
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> twostage_compress::Result<()> {
        match self {
            Self::Arx(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Narx(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Pca(c) => c.compress_into(inputs, outputs, work, alpha),
        }
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> twostage_compress::Result<()> {
        match self {
            Self::Arx(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Narx(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Pca(c) => c.compress_fast_into(inputs, outputs, work, alpha),
        }
    }

    fn feature_names(&self) -> Vec<String> {
        match self {
            Self::Arx(c) => c.feature_names(),
            Self::Narx(c) => c.feature_names(),
            Self::Pca(c) => c.feature_names(),
        }
    }
}

/// The fitting method of stage 2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum RegressorConfig {
    /// Linear (ridge) least squares.
    Linear(Ridge),
    /// A tanh network trained by Levenberg-Marquardt.
    Mlp(Mlp),
    /// A global network routing each record to a specialist network of its
    /// piece of the first parameter's range.
    Piecewise(Piecewise),
}

impl std::fmt::Display for RegressorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Linear(r) => write!(f, "linear (ridge lambda {:e})", r.lambda()),
            Self::Mlp(m) => write!(f, "MLP {:?} tanh, Levenberg-Marquardt", m.params().hidden()),
            Self::Piecewise(p) => write!(
                f,
                "{} x MLP {:?} by pieces",
                p.pieces(),
                p.global().params().hidden()
            ),
        }
    }
}

impl RegressorConfig {
    /// Fit stage 2 on features `x` and parameters `y`; `seed` seeds the
    /// network's initial weights and held-out split, so that the run's one
    /// seed decides every random choice.
    pub(crate) fn fit(
        &self,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
        seed: u64,
    ) -> twostage_fit::Result<FittedRegressor> {
        Ok(match self {
            Self::Linear(r) => FittedRegressor::Linear(r.fit(x, y)?),
            Self::Mlp(m) => FittedRegressor::Mlp(m.with_seed(seed).fit(x, y)?),
            Self::Piecewise(p) => FittedRegressor::Piecewise(p.with_seed(seed).fit(x, y)?),
        })
    }
}

/// A fitted stage-2 map h.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum FittedRegressor {
    /// A linear map.
    Linear(FittedLinear),
    /// A network.
    Mlp(FittedMlp),
    /// Networks by pieces.
    Piecewise(FittedPiecewise),
}

impl Predictor for FittedRegressor {
    fn n_inputs(&self) -> usize {
        match self {
            Self::Linear(m) => m.n_inputs(),
            Self::Mlp(m) => m.n_inputs(),
            Self::Piecewise(m) => m.n_inputs(),
        }
    }

    fn n_outputs(&self) -> usize {
        match self {
            Self::Linear(m) => m.n_outputs(),
            Self::Mlp(m) => m.n_outputs(),
            Self::Piecewise(m) => m.n_outputs(),
        }
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> twostage_fit::Result<()> {
        match self {
            Self::Linear(m) => m.predict_into(x, out),
            Self::Mlp(m) => m.predict_into(x, out),
            Self::Piecewise(m) => m.predict_into(x, out),
        }
    }
}
