//! The leading principal components of the output record: a stage-1
//! compressor for experiments that all share one input signal.

use crate::InvalidSetting;
use faer::Par;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::Compressor;
use crate::arx::MAX_SIGNALS;
use crate::error::{CompressError, Result};
use crate::signals::check_fixed_record;
use crate::workspace::Workspace;

const MAX_COMPONENTS: usize = 64;

/// Scores of the output record on its leading principal directions:
/// `alpha_i = v_i' (y - y_mean)`, with `v_1, v_2, ...` the principal
/// directions of the training outputs (all samples of all outputs stacked
/// in one vector per record), strongest first.
///
/// When every experiment applies the same input, as the car's chicane, the
/// output record itself summarizes the experiment, and its leading
/// components keep what varies with theta while averaging the measurement
/// noise over all N samples. The input is ignored, so this compressor is
/// *only* valid for a fixed input; records must have the training length.
///
/// A new `OutputPca` is unfitted; [`OutputPca::fit`] learns the mean and
/// directions from training outputs (the facade does this from the first
/// records of the training design).
///
/// | setting | default | valid |
/// |---|---|---|
/// | `components` | none | 1..=64, fewer than the fitting records |
///
/// ```
/// use ndarray::Array2;
/// use twostage_compress::{Compressor, OutputPca};
///
/// // Records y = a * sin + b * cos + 0.001 * wiggle on 100 samples: two
/// // directions carry everything.
/// let wave = |k: usize, f: fn(f64) -> f64| f(k as f64 * 0.1);
/// let records: Vec<Array2<f64>> = (0..40)
///     .map(|r| {
///         let (a, b) = ((r % 7) as f64 - 3.0, (r % 5) as f64 - 2.0);
///         Array2::from_shape_fn((100, 1), |(k, _)| {
///             a * wave(k, f64::sin) + b * wave(k, f64::cos) + 1e-3 * ((k * r) % 3) as f64
///         })
///     })
///     .collect();
/// let views: Vec<_> = records.iter().map(|r| r.view()).collect();
/// let pca = OutputPca::new(2)?.fit(&views)?;
/// assert_eq!(pca.n_features(), 2);
/// let u = Array2::<f64>::zeros((100, 1));
/// let alpha = pca.compress(u.view(), records[3].view())?;
/// assert_eq!(alpha.len(), 2);
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "PcaFields")]
pub struct OutputPca {
    components: usize,
    /// Samples per record; 0 until fitted.
    n_samples: usize,
    n_inputs: usize,
    n_outputs: usize,
    /// Mean output record, output after output (column-major like `IoData`).
    mean: Vec<f64>,
    /// `components` directions of length `n_samples * n_outputs`, row-major.
    basis: Vec<f64>,
}

#[derive(Deserialize)]
struct PcaFields {
    components: usize,
    n_samples: usize,
    n_inputs: usize,
    n_outputs: usize,
    mean: Vec<f64>,
    basis: Vec<f64>,
}

impl TryFrom<PcaFields> for OutputPca {
    type Error = CompressError;
    fn try_from(f: PcaFields) -> Result<Self> {
        let pca = Self::new(f.components)?;
        if f.n_samples == 0 {
            return Ok(pca);
        }
        let d = f.n_samples.checked_mul(f.n_outputs);
        let consistent = f.n_inputs <= MAX_SIGNALS
            && (1..=MAX_SIGNALS).contains(&f.n_outputs)
            && d.is_some_and(|d| f.mean.len() == d)
            && d.and_then(|d| d.checked_mul(f.components)) == Some(f.basis.len())
            && f.mean.iter().chain(&f.basis).all(|v| v.is_finite());
        if !consistent {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "PCA basis",
                value: format!("{} values", f.basis.len()),
                reason: "does not match the stored record shape (the data is corrupted)".into(),
            }));
        }
        Ok(Self {
            components: f.components,
            n_samples: f.n_samples,
            n_inputs: f.n_inputs,
            n_outputs: f.n_outputs,
            mean: f.mean,
            basis: f.basis,
        })
    }
}

impl OutputPca {
    /// An unfitted compressor keeping `components` principal components.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] outside 1..=64.
    pub fn new(components: usize) -> Result<Self> {
        if !(1..=MAX_COMPONENTS).contains(&components) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "components",
                value: components.to_string(),
                reason: "must lie in 1..=64".into(),
            }));
        }
        Ok(Self {
            components,
            n_samples: 0,
            n_inputs: 1,
            n_outputs: 1,
            mean: Vec::new(),
            basis: Vec::new(),
        })
    }

    /// Number of components kept.
    pub fn components(&self) -> usize {
        self.components
    }

    /// Whether [`OutputPca::fit`] has run.
    pub fn is_fitted(&self) -> bool {
        self.n_samples > 0
    }

    /// The principal directions, strongest first (each of length N x n_y).
    pub fn directions(&self) -> impl Iterator<Item = &[f64]> {
        let d = self.n_samples * self.n_outputs;
        self.basis.chunks_exact(d.max(1)).take(self.components)
    }

    /// Learn the mean and the leading directions from training output
    /// records (each N x n_y, all of one shape). Deterministic: the same
    /// records give the same bits on any machine and thread count.
    ///
    /// # Errors
    /// No records, records of different shapes or with non-finite values,
    /// fewer records than components + 1, or records that do not vary in
    /// as many directions as components are asked for.
    pub fn fit(mut self, outputs: &[ArrayView2<'_, f64>]) -> Result<Self> {
        let Some(first) = outputs.first() else {
            return Err(self.too_few(0));
        };
        let (n, ny) = first.dim();
        let d = n * ny;
        let m = outputs.len();
        if m <= self.components {
            return Err(self.too_few(m));
        }
        // Records as rows of a centred m x d matrix.
        let mut x = vec![0.0; m * d];
        for (row, record) in x.chunks_exact_mut(d).zip(outputs) {
            if record.dim() != (n, ny) {
                return Err(CompressError::FixedLength {
                    expected: n,
                    got: record.nrows(),
                    structure: self.to_string(),
                });
            }
            for (j, column) in record.columns().into_iter().enumerate() {
                for (k, v) in column.iter().enumerate() {
                    if !v.is_finite() {
                        return Err(CompressError::NonFinite {
                            signal: crate::signals::name("y", j, ny),
                            index: k,
                            value: *v,
                        });
                    }
                    row[j * n + k] = *v;
                }
            }
        }
        let mut mean = vec![0.0; d];
        for row in x.chunks_exact(d) {
            for (a, v) in mean.iter_mut().zip(row) {
                *a += v / m as f64;
            }
        }
        for row in x.chunks_exact_mut(d) {
            for (v, a) in row.iter_mut().zip(&mean) {
                *v -= a;
            }
        }
        // Principal directions are the leading right singular vectors of
        // X, by a thin SVD: the Gram matrix's eigenvectors would square
        // the condition number. Each is checked for variance before it is
        // kept: directions with none are rounding noise.
        let total: f64 = x.iter().map(|v| v * v).sum();
        let tolerance = 1e-20 * total;
        let (vectors, variances) =
            leading_directions(&x, m, d, self.components).ok_or_else(|| {
                CompressError::RankDeficient {
                    structure: self.to_string(),
                    cause: "the singular value decomposition of the outputs did not converge \
                            (non-finite or wildly scaled outputs?)"
                        .into(),
                }
            })?;
        if let Some(i) = variances.iter().position(|v| v.is_nan() || *v <= tolerance) {
            return Err(CompressError::RankDeficient {
                structure: self.to_string(),
                cause: format!(
                    "the training outputs vary in only {i} directions: ask for at most {i} \
                     components"
                ),
            });
        }
        let basis = vectors;
        self.n_samples = n;
        self.n_outputs = ny;
        self.mean = mean;
        self.basis = basis;
        Ok(self)
    }

    /// The same fitted compressor for records with `n_inputs` inputs (the
    /// inputs are only checked for shape and finiteness, never used).
    ///
    /// # Errors
    /// More than 64 inputs.
    pub fn with_inputs(mut self, n_inputs: usize) -> Result<Self> {
        if n_inputs > MAX_SIGNALS {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "inputs",
                value: n_inputs.to_string(),
                reason: "at most 64".into(),
            }));
        }
        self.n_inputs = n_inputs;
        Ok(self)
    }

    fn too_few(&self, m: usize) -> CompressError {
        CompressError::InvalidSetting(InvalidSetting {
            name: "PCA records",
            value: m.to_string(),
            reason: format!(
                "fitting {} components needs at least {} records",
                self.components,
                self.components + 1
            ),
        })
    }
}

/// The `k` leading right singular vectors of the row-major m x d matrix
/// `x` (row-major, k x d, largest singular value first), each with a fixed
/// sign (its largest entry positive), and the variance along each (its
/// squared singular value), by faer's thin SVD on one thread (bitwise
/// reproducible on a given processor). `None` if it does not converge, or
/// if `x` has fewer than `k` singular values.
fn leading_directions(x: &[f64], m: usize, d: usize, k: usize) -> Option<(Vec<f64>, Vec<f64>)> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::svd::{ComputeSvdVectors, svd, svd_scratch};
    let rank = m.min(d);
    if k > rank {
        return None;
    }
    let matrix = faer::Mat::from_fn(m, d, |i, j| x[i * d + j]);
    let mut values = faer::diag::Diag::<f64>::zeros(rank);
    let mut v = faer::Mat::<f64>::zeros(d, rank);
    let scratch = svd_scratch::<f64>(
        m,
        d,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Thin,
        Par::Seq,
        Default::default(),
    );
    svd(
        matrix.as_ref(),
        values.as_mut(),
        None,
        Some(v.as_mut()),
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )
    .ok()?;
    // faer sorts the singular values in nonincreasing order.
    let mut leading = vec![0.0; k * d];
    for (column, out) in leading.chunks_exact_mut(d).enumerate() {
        for (o, r) in out.iter_mut().zip(0..d) {
            *o = v[(r, column)];
        }
        let sign = out
            .iter()
            .copied()
            .max_by(|x, y| x.abs().total_cmp(&y.abs()))
            .map_or(1.0, f64::signum);
        out.iter_mut().for_each(|v| *v *= sign);
    }
    let variances = (0..k).map(|i| values[i] * values[i]).collect();
    Some((leading, variances))
}

impl std::fmt::Display for OutputPca {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PCA({}) of the output", self.components)
    }
}

impl Compressor for OutputPca {
    fn n_features(&self) -> usize {
        self.components
    }

    fn feature_names(&self) -> Vec<String> {
        (1..=self.components).map(|i| format!("pc{i}")).collect()
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        _work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        if !self.is_fitted() {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "PCA",
                value: "unfitted".into(),
                reason: "fit it on training outputs first (OutputPca::fit)".into(),
            }));
        }
        check_fixed_record(
            inputs,
            outputs,
            self.n_inputs,
            self.n_outputs,
            self.n_samples,
            alpha.len(),
            self.components,
            self,
        )?;
        let d = self.n_samples * self.n_outputs;
        for (a, v) in alpha.iter_mut().zip(self.basis.chunks_exact(d)) {
            let mut acc = 0.0;
            for (j, column) in outputs.columns().into_iter().enumerate() {
                let offset = j * self.n_samples;
                for (k, y) in column.iter().enumerate() {
                    acc += v[offset + k] * (y - self.mean[offset + k]);
                }
            }
            *a = acc;
        }
        Ok(())
    }
}
