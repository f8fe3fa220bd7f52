//! Standardization of features and targets, learned on training data and
//! stored with the model.

use crate::InvalidSetting;
use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use crate::error::FitError;

/// Affine map `z = (x - mean) / scale` per column.
///
/// Columns with zero spread keep scale 1, so constant features map to 0
/// instead of dividing by zero.
///
/// ```
/// use ndarray::array;
/// use twostage_fit::Standardizer;
/// let x = array![[1.0, 10.0], [3.0, 10.0]];
/// let s = Standardizer::fit(x.view());
/// let mut z = [0.0; 2];
/// s.transform_into(&[3.0, 10.0], &mut z);
/// assert!((z[0] - 1.0).abs() < 1e-15 && z[1].abs() < 1e-15);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "StandardizerFields")]
pub struct Standardizer {
    mean: Vec<f64>,
    scale: Vec<f64>,
}

/// What a file stores; decoding checks it like [`Standardizer::fit`]'s
/// output: one finite mean and one finite positive scale per column.
#[derive(Deserialize)]
struct StandardizerFields {
    mean: Vec<f64>,
    scale: Vec<f64>,
}

impl TryFrom<StandardizerFields> for Standardizer {
    type Error = FitError;
    fn try_from(f: StandardizerFields) -> Result<Self, FitError> {
        if f.mean.len() != f.scale.len() {
            return Err(FitError::ShapeMismatch(format!(
                "standardizer with {} means and {} scales",
                f.mean.len(),
                f.scale.len()
            )));
        }
        if let Some(s) = f.scale.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "standardizer scale",
                value: s.to_string(),
                reason: "must be finite and > 0".into(),
            }));
        }
        if let Some(m) = f.mean.iter().find(|m| !m.is_finite()) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "standardizer mean",
                value: m.to_string(),
                reason: "must be finite".into(),
            }));
        }
        Ok(Self {
            mean: f.mean,
            scale: f.scale,
        })
    }
}

impl Standardizer {
    /// Learn means and (population) standard deviations of the columns of `x`.
    pub fn fit(x: ArrayView2<'_, f64>) -> Self {
        let n = x.nrows().max(1) as f64;
        let mut mean = Vec::with_capacity(x.ncols());
        let mut scale = Vec::with_capacity(x.ncols());
        for col in x.columns() {
            let m = col.iter().sum::<f64>() / n;
            let var = col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n;
            let sd = var.sqrt();
            mean.push(m);
            scale.push(if sd > 1e-300 * m.abs().max(1.0) {
                sd
            } else {
                1.0
            });
        }
        Self { mean, scale }
    }

    /// The identity map on `dim` columns.
    pub fn identity(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            scale: vec![1.0; dim],
        }
    }

    /// Number of columns.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Column means.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Column scales.
    pub fn scale(&self) -> &[f64] {
        &self.scale
    }

    /// `z = (x - mean) / scale` (slices of length [`Standardizer::dim`]).
    pub fn transform_into(&self, x: &[f64], z: &mut [f64]) {
        twostage_kernels::vector::standardize(x, &self.mean[..], &self.scale[..], z);
    }

    /// `x = mean + scale z`, in place.
    pub fn inverse_in_place(&self, z: &mut [f64]) {
        twostage_kernels::vector::unstandardize_in_place(z, &self.mean[..], &self.scale[..]);
    }

    /// Standardize every row of `x`.
    pub fn transform(&self, x: ArrayView2<'_, f64>) -> Array2<f64> {
        let mut z = x.to_owned();
        for mut row in z.rows_mut() {
            for (v, (m, s)) in row.iter_mut().zip(self.mean.iter().zip(&self.scale)) {
                *v = (*v - m) / s;
            }
        }
        z
    }
}
