//! Adaptive (normalized split-conformal) intervals: widths that follow each
//! record's difficulty instead of one width for all.

use ndarray::{Array2, ArrayView2, Axis};
use serde::{Deserialize, Serialize};
use twostage_fit::{FittedMlp, MlpParams, Predictor, Regressor};

use crate::error::{FileError, Result};

/// Normalized split-conformal intervals (Lei et al., 2018, Section 5.2):
/// a small network `sigma(x)` learns the typical absolute error of each
/// parameter from the features on one half of the calibration records; on
/// the other half the scores `|theta - theta_hat| / sigma(x)` give the
/// finite-sample conformal quantile `q`, and the interval of a record is
/// `theta_hat +- q sigma(x)`. Coverage is guaranteed at `1 - alpha` for
/// exchangeable records, as for the fixed-width intervals, but the width
/// now shrinks where the estimator is sure and grows where it is not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "AdaptiveFields")]
pub struct AdaptiveIntervals {
    alpha: f64,
    difficulty: FittedMlp,
    /// Lower bound of sigma per parameter, so that a network predicting
    /// (near) zero cannot make an interval collapse.
    floor: Vec<f64>,
    /// Conformal quantile of the normalized scores, per parameter.
    quantile: Vec<f64>,
    n_calibration: usize,
    /// Coverage on the validation records, per parameter, when validated.
    coverage: Option<Vec<f64>>,
    /// Mean half-width on the validation records, per parameter.
    mean_half_width: Option<Vec<f64>>,
}

#[derive(Deserialize)]
struct AdaptiveFields {
    alpha: f64,
    difficulty: FittedMlp,
    floor: Vec<f64>,
    quantile: Vec<f64>,
    n_calibration: usize,
    coverage: Option<Vec<f64>>,
    mean_half_width: Option<Vec<f64>>,
}

impl TryFrom<AdaptiveFields> for AdaptiveIntervals {
    type Error = FileError;
    fn try_from(f: AdaptiveFields) -> std::result::Result<Self, FileError> {
        let q = f.difficulty.n_outputs();
        let lengths_ok = f.floor.len() == q
            && f.quantile.len() == q
            && f.coverage.as_ref().is_none_or(|c| c.len() == q)
            && f.mean_half_width.as_ref().is_none_or(|w| w.len() == q);
        let values_ok = f.floor.iter().all(|v| v.is_finite() && *v > 0.0)
            && f.quantile.iter().all(|v| !v.is_nan() && *v >= 0.0)
            && f.alpha > 0.0
            && f.alpha < 1.0;
        if !(lengths_ok && values_ok) {
            return Err(FileError::Inconsistent {
                what: format!(
                    "adaptive intervals for {q} parameters with {} floors, {} quantiles, \
                     alpha {}",
                    f.floor.len(),
                    f.quantile.len(),
                    f.alpha
                ),
            });
        }
        Ok(Self {
            alpha: f.alpha,
            difficulty: f.difficulty,
            floor: f.floor,
            quantile: f.quantile,
            n_calibration: f.n_calibration,
            coverage: f.coverage,
            mean_half_width: f.mean_half_width,
        })
    }
}

/// Calibration records below which the intervals are not fitted: each
/// half needs enough rows for a small network and a stable quantile.
pub(crate) const MIN_ADAPTIVE_CALIBRATION: usize = 100;

impl AdaptiveIntervals {
    /// Fit on calibration `features` and residuals `truth - estimate`
    /// (rows are records): the first half trains sigma, the second
    /// calibrates the quantile.
    pub(crate) fn calibrate(
        features: ArrayView2<'_, f64>,
        residuals: ArrayView2<'_, f64>,
        alpha: f64,
        seed: u64,
    ) -> Result<Self> {
        let n = features.nrows();
        let half = n / 2;
        let (q, width) = (residuals.ncols(), features.ncols());
        let absolute = residuals.mapv(f64::abs);
        let (fit_x, score_x) = features.split_at(Axis(0), half);
        let (fit_r, score_r) = absolute.view().split_at(Axis(0), half);
        // A small network; its own held-out split stops it early.
        let hidden = (width / 2).clamp(3, 8);
        let difficulty = MlpParams::new(&[hidden])?
            .restarts(2)
            .seed(seed ^ 0x4144_4150_5449_5645) // "ADAPTIVE"
            .check()?
            .fit(fit_x, fit_r)?;
        let floor: Vec<f64> = (0..q)
            .map(|j| (0.1 * fit_r.column(j).mean().unwrap_or(0.0)).max(f64::MIN_POSITIVE))
            .collect();
        let mut intervals = Self {
            alpha,
            difficulty,
            floor,
            quantile: vec![0.0; q],
            n_calibration: n,
            coverage: None,
            mean_half_width: None,
        };
        let sigma = intervals.sigma(score_x)?;
        let m = score_x.nrows();
        let rank = ((m as f64 + 1.0) * (1.0 - alpha)).ceil() as usize;
        for j in 0..q {
            let mut scores: Vec<f64> = score_r
                .column(j)
                .iter()
                .zip(sigma.column(j))
                .map(|(r, s)| r / s)
                .collect();
            scores.sort_by(f64::total_cmp);
            intervals.quantile[j] = if rank > m || m == 0 {
                f64::INFINITY
            } else {
                scores[rank.max(1) - 1]
            };
        }
        Ok(intervals)
    }

    /// sigma(x) for each row of `features`, floored.
    fn sigma(&self, features: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
        let mut sigma = self.difficulty.predict(features)?;
        for mut row in sigma.rows_mut() {
            for (v, floor) in row.iter_mut().zip(&self.floor) {
                *v = if v.is_nan() { *floor } else { v.max(*floor) };
            }
        }
        Ok(sigma)
    }

    /// How many parameters it gives half-widths of.
    pub(crate) fn n_parameters(&self) -> usize {
        self.quantile.len()
    }

    /// Half-widths of the intervals of one record, from its features.
    ///
    /// # Errors
    /// Features or output of the wrong length.
    pub fn half_widths_into(&self, features: &[f64], out: &mut [f64]) -> Result<()> {
        self.difficulty.predict_into(features, out)?;
        for ((v, floor), quantile) in out.iter_mut().zip(&self.floor).zip(&self.quantile) {
            let sigma = if v.is_nan() { *floor } else { v.max(*floor) };
            *v = quantile * sigma;
        }
        Ok(())
    }

    /// Half-widths for each row of `features`.
    pub(crate) fn half_widths(&self, features: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
        let mut widths = self.sigma(features)?;
        for mut row in widths.rows_mut() {
            for (v, quantile) in row.iter_mut().zip(&self.quantile) {
                *v *= quantile;
            }
        }
        Ok(widths)
    }

    /// Record coverage and mean width on validation records.
    pub(crate) fn validate(
        &mut self,
        features: ArrayView2<'_, f64>,
        residuals: ArrayView2<'_, f64>,
    ) -> Result<()> {
        let widths = self.half_widths(features)?;
        let rows = residuals.nrows().max(1) as f64;
        let q = residuals.ncols();
        let mut coverage = vec![0.0; q];
        let mut mean = vec![0.0; q];
        for (r, w) in residuals.rows().into_iter().zip(widths.rows()) {
            for j in 0..q {
                coverage[j] += f64::from(u8::from(r[j].abs() <= w[j])) / rows;
                mean[j] += w[j] / rows;
            }
        }
        self.coverage = Some(coverage);
        self.mean_half_width = Some(mean);
        Ok(())
    }

    /// The floors, quantiles and difficulty network, for the runtime's
    /// export.
    pub(crate) fn parts(&self) -> (&[f64], &[f64], &FittedMlp) {
        (&self.floor, &self.quantile, &self.difficulty)
    }

    /// The miscoverage level alpha.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }
    /// Calibration records used (half for sigma, half for the quantile).
    pub fn n_calibration(&self) -> usize {
        self.n_calibration
    }
    /// Coverage on the validation records, per parameter, when validated.
    pub fn coverage(&self) -> Option<&[f64]> {
        self.coverage.as_deref()
    }
    /// Mean half-width on the validation records, per parameter.
    pub fn mean_half_width(&self) -> Option<&[f64]> {
        self.mean_half_width.as_deref()
    }
    /// The number of parameters.
    pub(crate) fn dim(&self) -> usize {
        self.quantile.len()
    }
    /// The number of features sigma reads.
    pub(crate) fn n_features(&self) -> usize {
        self.difficulty.n_inputs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// Errors whose spread grows with |x|: fixed-width intervals over-cover
    /// small |x| and under-cover large |x|; adaptive ones follow.
    #[test]
    fn widths_follow_the_error_scale_and_cover_at_their_level() {
        let noise = |i: usize| {
            // A fixed, roughly uniform sequence on [-1, 1].
            (((i * 7919 + 17) % 1000) as f64 / 500.0) - 1.0
        };
        let make = |rows: std::ops::Range<usize>| {
            let x = Array2::from_shape_fn((rows.len(), 1), |(k, _)| {
                ((rows.start + k) % 97) as f64 / 48.0 - 1.0
            });
            let r = Array2::from_shape_fn((rows.len(), 1), |(k, _)| {
                (0.05 + x[[k, 0]].abs()) * noise(rows.start + k + 5000)
            });
            (x, r)
        };
        let (x, r) = make(0..2000);
        let a = AdaptiveIntervals::calibrate(x.view(), r.view(), 0.1, 1).unwrap();
        let (xv, rv) = make(2000..6000);
        let mut a = a;
        a.validate(xv.view(), rv.view()).unwrap();
        let coverage = a.coverage().unwrap()[0];
        assert!((coverage - 0.9).abs() < 0.03, "coverage {coverage}");
        let mut narrow = [0.0];
        let mut wide = [0.0];
        a.half_widths_into(&[0.0], &mut narrow).unwrap();
        a.half_widths_into(&[0.95], &mut wide).unwrap();
        assert!(wide[0] > 4.0 * narrow[0], "{narrow:?} vs {wide:?}");
        // At |x| = 0.95 the 90% half-width of a uniform error of scale 1.0
        // is 0.9: the interval should be near it.
        assert!((wide[0] - 0.9).abs() < 0.2, "{wide:?}");
    }
}
