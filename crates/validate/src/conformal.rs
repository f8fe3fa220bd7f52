//! Split-conformal prediction intervals (Vovk, Gammerman and Shafer;
//! Lei et al., "Distribution-free predictive inference for regression",
//! JASA 2018): from n calibration residuals, the interval
//! `estimate +- q` with q the ceil((n + 1)(1 - alpha))-th smallest absolute
//! residual covers a fresh truth with probability at least 1 - alpha.

use crate::InvalidSetting;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::error::{Result, ValidateError};

/// Per-parameter half-widths of split-conformal intervals at level `1 - alpha`.
///
/// ```
/// use ndarray::Array2;
/// use twostage_validate::ConformalIntervals;
/// // Residuals 1..=19 for one parameter; alpha = 0.1: rank ceil(20 * 0.9) = 18.
/// let residuals = Array2::from_shape_fn((19, 1), |(i, _)| (i + 1) as f64);
/// let c = ConformalIntervals::calibrate(residuals.view(), 0.1)?;
/// assert!((c.half_widths()[0] - 18.0).abs() < 1e-12);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConformalIntervals {
    alpha: f64,
    n_calibration: usize,
    half_widths: Vec<f64>,
}

impl ConformalIntervals {
    /// Calibrate on residuals `truth - estimate` (calibration records x
    /// parameters). A level that needs more calibration records than given
    /// yields infinite half-widths, as the method prescribes.
    ///
    /// # Errors
    /// `alpha` outside (0, 1), no residuals, or a non-finite residual.
    pub fn calibrate(residuals: ArrayView2<'_, f64>, alpha: f64) -> Result<Self> {
        if !(alpha > 0.0 && alpha < 1.0) {
            return Err(InvalidSetting::new("alpha", alpha, "must lie in (0, 1)").into());
        }
        let n = residuals.nrows();
        if n == 0 || residuals.ncols() == 0 {
            return Err(ValidateError::InvalidErrors(
                "no calibration residuals: simulate at least one calibration record".into(),
            ));
        }
        let rank = ((n as f64 + 1.0) * (1.0 - alpha)).ceil() as usize;
        let mut half_widths = Vec::with_capacity(residuals.ncols());
        let mut sorted = Vec::with_capacity(n);
        for (j, column) in residuals.columns().into_iter().enumerate() {
            sorted.clear();
            for (i, r) in column.iter().enumerate() {
                if !r.is_finite() {
                    return Err(ValidateError::InvalidErrors(format!(
                        "calibration residual {i} of parameter {j} is {r}"
                    )));
                }
                sorted.push(r.abs());
            }
            sorted.sort_by(f64::total_cmp);
            half_widths.push(if rank > n {
                f64::INFINITY
            } else {
                sorted[rank.max(1) - 1]
            });
        }
        Ok(Self {
            alpha,
            n_calibration: n,
            half_widths,
        })
    }

    /// The miscoverage level alpha.
    pub fn alpha(&self) -> f64 {
        self.alpha
    }
    /// Number of calibration records.
    pub fn n_calibration(&self) -> usize {
        self.n_calibration
    }
    /// Half-width per parameter.
    pub fn half_widths(&self) -> &[f64] {
        &self.half_widths
    }

    /// The intervals of the parameters at `places` alone, in that order
    /// (an estimator's other parameters held at values).
    ///
    /// ```
    /// use twostage_validate::ConformalIntervals;
    /// let residuals = ndarray::array![[0.1, -2.0], [-0.3, 1.0], [0.2, 0.5]];
    /// let both = ConformalIntervals::calibrate(residuals.view(), 0.5)?;
    /// let second = both.of_parameters(&[1]);
    /// assert_eq!(second.half_widths(), &both.half_widths()[1..]);
    /// assert_eq!((second.alpha(), second.n_calibration()), (0.5, 3));
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    ///
    /// # Panics
    /// A place beyond the parameters (a caller's bug, not data).
    pub fn of_parameters(&self, places: &[usize]) -> Self {
        Self {
            alpha: self.alpha,
            n_calibration: self.n_calibration,
            half_widths: places.iter().map(|&j| self.half_widths[j]).collect(),
        }
    }

    /// The share of `(truth, estimate)` rows whose truth lies in the interval,
    /// per parameter.
    pub fn coverage(&self, truth: ArrayView2<'_, f64>, estimates: ArrayView2<'_, f64>) -> Vec<f64> {
        let n = truth.nrows().max(1) as f64;
        (0..self.half_widths.len())
            .map(|j| {
                let inside = truth
                    .column(j)
                    .iter()
                    .zip(estimates.column(j))
                    .filter(|(t, e)| (*t - *e).abs() <= self.half_widths[j])
                    .count();
                inside as f64 / n
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn the_finite_sample_rank_and_infinite_widths() {
        // n = 9, alpha = 0.1: rank ceil(10 * 0.9) = 9, the largest residual.
        let r = Array2::from_shape_fn((9, 2), |(i, j)| {
            (i as f64 + 1.0) * if j == 0 { 1.0 } else { -2.0 }
        });
        let c = ConformalIntervals::calibrate(r.view(), 0.1).unwrap();
        assert_eq!(c.half_widths(), &[9.0, 18.0]);
        // n = 5, alpha = 0.1: rank ceil(6 * 0.9) = 6 > 5: no finite interval.
        let c = ConformalIntervals::calibrate(r.slice(ndarray::s![..5, ..]), 0.1).unwrap();
        assert!(c.half_widths()[0].is_infinite());
        assert!(ConformalIntervals::calibrate(r.view(), 0.0).is_err());
    }

    #[test]
    fn coverage_holds_on_exchangeable_residuals() {
        // Residuals from a fixed heavy-tailed sequence: calibrate on the first
        // half, check coverage on the second (exchangeable by construction).
        let mut uniform = crate::tests::uniform_stream(99);
        let mut next = || {
            let u = uniform();
            (u - 0.5) / (u * (1.0 - u)).sqrt()
        };
        let all = Array2::from_shape_fn((4000, 1), |_| next());
        let c = ConformalIntervals::calibrate(all.slice(ndarray::s![..2000, ..]), 0.1).unwrap();
        let zeros = Array2::zeros((2000, 1));
        let cover = c.coverage(all.slice(ndarray::s![2000.., ..]), zeros.view())[0];
        // Expected at least 0.9 (and at most 0.9 + 1/(n+1)); sampling error ~0.007.
        assert!((0.88..0.925).contains(&cover), "coverage {cover}");
    }
}
