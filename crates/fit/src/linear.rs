//! Linear (ridge) least squares: the paper's simplest stage-2 map,
//! `h(alpha) = c_1 alpha_1 + ... + c_n alpha_n` (Section 3.2), with an
//! intercept and standardized features.

use crate::InvalidSetting;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::{factor, solve};
use faer::{Mat, Par};
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::check;
use crate::error::{FitError, Result};
use crate::standardize::Standardizer;
use crate::{Predictor, Regressor};

/// Ridge regression, solved as the least-squares problem
/// `[Z; sqrt(lambda) I] W = [T; 0]` by QR (never the normal equations),
/// where Z and T are the standardized features and targets.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `lambda` | 1e-8 | finite, >= 0 (0: plain least squares, rank checked) |
///
/// ```
/// use ndarray::Array2;
/// use twostage_fit::{Predictor, Regressor, Ridge};
/// // t = 2 x1 - x2 + 3, exactly.
/// let x = Array2::from_shape_fn((20, 2), |(i, j)| ((i * (j + 3)) % 7) as f64);
/// let t = Array2::from_shape_fn((20, 1), |(i, _)| 2.0 * x[[i, 0]] - x[[i, 1]] + 3.0);
/// let model = Ridge::new(0.0)?.fit(x.view(), t.view())?;
/// let mut out = [0.0];
/// model.predict_into(&[1.0, 1.0], &mut out)?;
/// assert!((out[0] - 4.0).abs() < 1e-10);
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ridge {
    lambda: f64,
}

impl Default for Ridge {
    fn default() -> Self {
        Self { lambda: 1e-8 }
    }
}

impl Ridge {
    /// Ridge with penalty `lambda` on the standardized weights.
    ///
    /// # Errors
    /// [`FitError::InvalidSetting`] unless `lambda` is finite and >= 0.
    pub fn new(lambda: f64) -> Result<Self> {
        if !(lambda.is_finite() && lambda >= 0.0) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "lambda",
                value: lambda.to_string(),
                reason: "must be finite and >= 0".into(),
            }));
        }
        Ok(Self { lambda })
    }

    /// The penalty.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }
}

/// A fitted linear map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FittedLinearFields")]
pub struct FittedLinear {
    features: Standardizer,
    targets: Standardizer,
    /// Weights in standardized units, row-major `n_targets x n_features`.
    weights: Vec<f64>,
}

/// What a file stores; decoding checks that the shapes agree.
#[derive(Deserialize)]
struct FittedLinearFields {
    features: Standardizer,
    targets: Standardizer,
    weights: Vec<f64>,
}

impl TryFrom<FittedLinearFields> for FittedLinear {
    type Error = FitError;
    fn try_from(f: FittedLinearFields) -> Result<Self> {
        let expected = f.features.dim().checked_mul(f.targets.dim());
        if expected != Some(f.weights.len()) || f.targets.dim() == 0 {
            return Err(FitError::ShapeMismatch(format!(
                "linear map with {} weights for {} features and {} targets",
                f.weights.len(),
                f.features.dim(),
                f.targets.dim()
            )));
        }
        Ok(Self {
            features: f.features,
            targets: f.targets,
            weights: f.weights,
        })
    }
}

impl FittedLinear {
    /// The standardization of the inputs.
    pub fn feature_scaling(&self) -> &Standardizer {
        &self.features
    }
    /// The standardization of the outputs.
    pub fn target_scaling(&self) -> &Standardizer {
        &self.targets
    }
    /// Row-major weights on standardized inputs: row k gives output k.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
}

impl Regressor for Ridge {
    type Model = FittedLinear;

    fn fit(&self, x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<FittedLinear> {
        check::training_data(x, y)?;
        let (m, n) = x.dim();
        let q = y.ncols();
        if self.lambda == 0.0 && m < n {
            return Err(FitError::TooFewSamples {
                got: m,
                needed: n,
                why: "plain least squares needs as many samples as features".into(),
            });
        }
        let features = Standardizer::fit(x);
        let targets = Standardizer::fit(y);
        let z = features.transform(x);
        let t = targets.transform(y);
        let extra = if self.lambda > 0.0 { n } else { 0 };
        let root = self.lambda.sqrt();
        let a = Mat::from_fn(m + extra, n, |i, j| {
            if i < m {
                z[[i, j]]
            } else if i - m == j {
                root
            } else {
                0.0
            }
        });
        let mut rhs = Mat::from_fn(m + extra, q, |i, j| if i < m { t[[i, j]] } else { 0.0 });
        // Sequential, so that the bits do not depend on the thread count
        // (faer's parallel blocked updates sum in another order).
        let (mut a, rows) = (a, m + extra);
        let block = factor::recommended_block_size::<f64>(rows, n);
        let mut q_coeff = Mat::<f64>::zeros(block, rows.min(n));
        let mut memory = MemBuffer::new(
            factor::qr_in_place_scratch::<f64>(rows, n, block, Par::Seq, Default::default()).or(
                solve::solve_lstsq_in_place_scratch::<f64>(rows, n, block, q, Par::Seq),
            ),
        );
        factor::qr_in_place(
            a.as_mut(),
            q_coeff.as_mut(),
            Par::Seq,
            MemStack::new(&mut memory),
            Default::default(),
        );
        // R is the upper triangle of `a` now.
        let largest = (0..n).map(|j| a[(j, j)].abs()).fold(0.0f64, f64::max);
        let dependent = |j: usize| {
            let d = a[(j, j)].abs();
            d.is_nan() || d <= 1e-12 * largest
        };
        if let Some(j) = (0..n).find(|&j| dependent(j)) {
            return Err(FitError::RankDeficient { feature: j });
        }
        solve::solve_lstsq_in_place(
            a.as_ref(),
            q_coeff.as_ref(),
            a.as_ref(),
            rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut memory),
        );
        let weights = (0..q)
            .flat_map(|k| (0..n).map(move |j| (k, j)))
            .map(|(k, j)| rhs[(j, k)])
            .collect();
        Ok(FittedLinear {
            features,
            targets,
            weights,
        })
    }
}

impl Predictor for FittedLinear {
    fn n_inputs(&self) -> usize {
        self.features.dim()
    }

    fn n_outputs(&self) -> usize {
        self.targets.dim()
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()> {
        let n = self.n_inputs();
        check::row_lengths(x, out, n, self.n_outputs())?;
        // Standardize on the fly: no scratch buffer on the hot path.
        for (k, o) in out.iter_mut().enumerate() {
            let w = &self.weights[k * n..(k + 1) * n];
            let mut acc = 0.0;
            for (j, wj) in w.iter().enumerate() {
                acc += wj * (x[j] - self.features.mean()[j]) / self.features.scale()[j];
            }
            *o = acc;
        }
        self.targets.inverse_in_place(out);
        Ok(())
    }
}
