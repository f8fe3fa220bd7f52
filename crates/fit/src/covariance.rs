//! The sample covariance of feature vectors and its Cholesky factor: what
//! a Mahalanobis distance or a weighting by the inverse covariance needs.

use ndarray::ArrayView2;
use twostage_kernels::cholesky::{PivotRule, cholesky_in_place, solve_lower_in_place};

/// Mean and lower Cholesky factor `L` (`C = L L'`) of the sample covariance
/// `C` of the rows of a matrix.
///
/// ```
/// use ndarray::array;
/// use twostage_fit::CovarianceFactor;
/// // Zero means; sums of squares 4, 4 and of products 2 over 6 rows, so
/// // C = [[0.8, 0.4], [0.4, 0.8]] and (1, 1) C^-1 (1, 1)' = 0.8 / 0.48.
/// let x = array![[1.0, 1.0], [-1.0, -1.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]];
/// let c = CovarianceFactor::of_rows(x.view()).expect("non-singular");
/// let mut z = [1.0, 1.0];
/// c.whiten(&mut z);
/// assert!((z[0] * z[0] + z[1] * z[1] - 0.8 / 0.48).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CovarianceFactor {
    /// Column means.
    pub mean: Vec<f64>,
    /// `L`, row-major n x n, lower triangular.
    pub factor: Vec<f64>,
}

impl CovarianceFactor {
    /// The factor of the rows' sample covariance (divisor m - 1); `None`
    /// with fewer than two rows or when a pivot falls below 1e-12 of the
    /// largest variance (a feature that does not vary, or one that is a
    /// combination of others).
    pub fn of_rows(rows: ArrayView2<'_, f64>) -> Option<Self> {
        let (m, n) = rows.dim();
        if m < 2 || n == 0 {
            return None;
        }
        let mean: Vec<f64> = rows
            .columns()
            .into_iter()
            .map(|c| c.sum() / m as f64)
            .collect();
        let mut factor = vec![0.0; n * n];
        for row in rows.rows() {
            for a in 0..n {
                let da = row[a] - mean[a];
                for b in 0..=a {
                    factor[a * n + b] += da * (row[b] - mean[b]);
                }
            }
        }
        for v in &mut factor {
            *v /= (m - 1) as f64;
        }
        cholesky_in_place(&mut factor, n, PivotRule::RelativeToLargest(1e-12)).ok()?;
        Some(Self { mean, factor })
    }

    /// Solve `L z = v` in place: `|z|^2 = v' C^-1 v`.
    pub fn whiten(&self, v: &mut [f64]) {
        solve_lower_in_place(&self.factor[..], self.mean.len(), v);
    }
}
