//! Where the training features lie, so that an estimate can say when its
//! record looks like nothing the estimator was trained on.

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
use twostage_fit::CovarianceFactor;
use twostage_kernels::cholesky::solve_lower_in_place;

/// The share of training features inside the envelope.
pub const ENVELOPE_LEVEL: f64 = 0.999;

/// The Mahalanobis envelope of the training features: their mean, the
/// Cholesky factor of their covariance, and the 99.9% quantile of the
/// training features' own distances. A record whose features lie farther
/// out is out of distribution: the network extrapolates there, and neither
/// the validation report nor the intervals speak for it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "EnvelopeFields")]
pub struct FeatureEnvelope {
    mean: Vec<f64>,
    /// Lower-triangular, row-major n x n.
    factor: Vec<f64>,
    threshold: f64,
}

#[derive(Deserialize)]
struct EnvelopeFields {
    mean: Vec<f64>,
    factor: Vec<f64>,
    threshold: f64,
}

impl TryFrom<EnvelopeFields> for FeatureEnvelope {
    type Error = crate::FileError;
    fn try_from(f: EnvelopeFields) -> Result<Self, crate::FileError> {
        let n = f.mean.len();
        let diagonal_ok = (0..n).all(|j| {
            f.factor
                .get(j * n + j)
                .is_some_and(|d| d.is_finite() && *d > 0.0)
        });
        if n.checked_mul(n) != Some(f.factor.len())
            || !diagonal_ok
            || f.factor.iter().chain(&f.mean).any(|v| !v.is_finite())
            || !(f.threshold.is_finite() && f.threshold >= 0.0)
        {
            return Err(crate::FileError::Inconsistent {
                what: format!(
                    "a feature envelope of {n} means, {} factor entries and threshold {}",
                    f.factor.len(),
                    f.threshold
                ),
            });
        }
        Ok(Self {
            mean: f.mean,
            factor: f.factor,
            threshold: f.threshold,
        })
    }
}

impl FeatureEnvelope {
    /// Fit on training features (rows are experiments). `None` when there
    /// are too few rows or a feature does not vary (the covariance is then
    /// singular and the distance undefined).
    pub(crate) fn fit(features: ArrayView2<'_, f64>) -> Option<Self> {
        let (m, n) = features.dim();
        if m <= n + 1 {
            return None;
        }
        let CovarianceFactor { mean, factor } = CovarianceFactor::of_rows(features)?;
        let mut envelope = Self {
            mean,
            factor,
            threshold: 0.0,
        };
        let mut distances: Vec<f64> = features
            .rows()
            .into_iter()
            .map(|row| envelope.distance_of(row.iter().copied()))
            .collect();
        distances.sort_by(f64::total_cmp);
        // The finite-sample rank of the conformal quantile: a fresh
        // training-like record falls inside with probability >= 99.9%.
        let rank = ((m as f64 + 1.0) * ENVELOPE_LEVEL).ceil() as usize;
        envelope.threshold = distances[rank.clamp(1, m) - 1];
        Some(envelope)
    }

    /// Replace the in-sample threshold by the conformal quantile of fresh
    /// records' distances (the calibration records): a fresh record of the
    /// model is then flagged with probability at most 0.1%. Without enough
    /// records for that rank (fewer than 999) the training quantile stays.
    pub(crate) fn recalibrate(&mut self, features: ArrayView2<'_, f64>) {
        let n = features.nrows();
        let rank = ((n as f64 + 1.0) * ENVELOPE_LEVEL).ceil() as usize;
        if rank > n || features.ncols() != self.mean.len() {
            return;
        }
        let mut distances: Vec<f64> = features
            .rows()
            .into_iter()
            .map(|row| self.distance_of(row.iter().copied()))
            .collect();
        distances.sort_by(f64::total_cmp);
        self.threshold = distances[rank.max(1) - 1];
    }

    /// The Mahalanobis distance of `features` from the training mean.
    pub fn distance(&self, features: &[f64]) -> f64 {
        if features.len() != self.mean.len() {
            return f64::INFINITY;
        }
        self.distance_of(features.iter().copied())
    }

    fn distance_of(&self, features: impl Iterator<Item = f64>) -> f64 {
        // |L^-1 (x - mean)|. Allocated per call: the CLI and batch paths
        // call this, not the estimate hot path.
        let mut z: Vec<f64> = features.zip(&self.mean).map(|(x, m)| x - m).collect();
        solve_lower_in_place(&self.factor[..], self.mean.len(), &mut z);
        z.iter().map(|v| v * v).sum::<f64>().sqrt()
    }

    /// The mean and the row-major lower Cholesky factor of the features'
    /// covariance, for the runtime's export.
    pub(crate) fn parts(&self) -> (&[f64], &[f64]) {
        (&self.mean, &self.factor)
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The distance beyond which a record is out of distribution.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn the_distance_is_the_quadratic_form_with_the_inverse_covariance() {
        // Two correlated features from a fixed deterministic sequence.
        let x = Array2::from_shape_fn((400, 2), |(i, j)| {
            let a = ((i * 37 + 11) % 101) as f64 / 50.0 - 1.0;
            let b = ((i * 53 + 7) % 89) as f64 / 44.0 - 1.0;
            if j == 0 { a } else { 0.5 * a + b }
        });
        let e = FeatureEnvelope::fit(x.view()).expect("non-singular");
        // Closed-form inverse of the 2 x 2 sample covariance.
        let m = 400.0;
        let mean = [x.column(0).sum() / m, x.column(1).sum() / m];
        let c = |a: usize, b: usize| {
            x.rows()
                .into_iter()
                .map(|r| (r[a] - mean[a]) * (r[b] - mean[b]))
                .sum::<f64>()
                / (m - 1.0)
        };
        let (c00, c01, c11) = (c(0, 0), c(0, 1), c(1, 1));
        let det = c00 * c11 - c01 * c01;
        let point = [0.7, -1.3];
        let d = [point[0] - mean[0], point[1] - mean[1]];
        let q = (c11 * d[0] * d[0] - 2.0 * c01 * d[0] * d[1] + c00 * d[1] * d[1]) / det;
        assert!((e.distance(&point) - q.sqrt()).abs() < 1e-12);
        // 99.9% of 400: rank ceil(401 * 0.999) = 401 > 400, so the largest.
        let largest = x
            .rows()
            .into_iter()
            .map(|r| e.distance(&[r[0], r[1]]))
            .fold(0.0, f64::max);
        assert_eq!(e.threshold().to_bits(), largest.to_bits());
        assert!(e.distance(&[1.0]).is_infinite());
    }

    #[test]
    fn a_constant_feature_gives_no_envelope() {
        let x = Array2::from_shape_fn((50, 2), |(i, j)| if j == 0 { i as f64 } else { 3.0 });
        assert!(FeatureEnvelope::fit(x.view()).is_none());
    }

    #[test]
    fn fresh_records_set_the_threshold_when_there_are_enough() {
        let make = |rows: usize, offset: usize| {
            Array2::from_shape_fn((rows, 2), |(i, j)| {
                let k = i + offset;
                ((k * (37 + 16 * j) + 11 * j) % 101) as f64 / 50.0 - 1.0
            })
        };
        let mut e = FeatureEnvelope::fit(make(400, 0).view()).expect("non-singular");
        let before = e.threshold();
        e.recalibrate(make(500, 400).view());
        assert_eq!(e.threshold().to_bits(), before.to_bits(), "500 < 999: kept");
        let fresh = make(2000, 900);
        e.recalibrate(fresh.view());
        // rank ceil(2001 * 0.999) = 1999: the second largest fresh distance.
        let mut d: Vec<f64> = fresh
            .rows()
            .into_iter()
            .map(|r| e.distance(&[r[0], r[1]]))
            .collect();
        d.sort_by(f64::total_cmp);
        assert_eq!(e.threshold().to_bits(), d[1998].to_bits());
    }
}
