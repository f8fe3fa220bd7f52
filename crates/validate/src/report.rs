//! The validation report of a trained estimator.

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::betting::BettingBound;
use crate::conformal::ConformalIntervals;
use crate::error::{Result, ValidateError};
use crate::hoeffding::{HoeffdingBound, squared_error_bound};

/// Accuracy of one parameter on the validation simulations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterReport {
    /// The parameter's name.
    pub name: String,
    /// Mean squared error.
    pub mse: f64,
    /// Root mean squared error.
    pub rmse: f64,
    /// Mean of estimate - truth.
    pub bias: f64,
    /// Coefficient of determination, 1 - MSE / var(truth).
    pub r2: f64,
    /// Largest absolute error.
    pub max_abs_error: f64,
    /// Theorem 1 for this parameter alone, at confidence `1 - delta / q`
    /// (union bound: all q parameter bounds hold together with probability
    /// at least 1 - delta), with sigma = the squared width of its box.
    pub hoeffding: HoeffdingBound,
    /// The betting certificate for this parameter alone, at the same
    /// confidence `1 - delta / q` as `hoeffding` (absent in reports read
    /// from estimator files before format version 4).
    pub certified: Option<BettingBound>,
    /// Half-width of the conformal interval, if calibrated.
    pub interval_half_width: Option<f64>,
    /// Share of validation truths inside their interval, if calibrated.
    pub interval_coverage: Option<f64>,
}

/// Validation of an estimator on r fresh simulations.
///
/// ```
/// use ndarray::array;
/// use twostage_validate::ValidationReport;
/// let truth = array![[0.1], [0.5], [-0.3], [0.8]];
/// let estimate = array![[0.12], [0.45], [-0.3], [0.83]];
/// let report = ValidationReport::new(&["theta".into()], truth.view(), estimate.view(), &[-0.9], &[0.9], 1e-3, None)?;
/// let p = &report.parameters[0];
/// assert!((p.mse - (0.0004 + 0.0025 + 0.0 + 0.0009) / 4.0).abs() < 1e-12);
/// assert!(report.total.upper() > p.mse);
/// // The betting certificate, stated for the RMSE of each parameter.
/// assert!(p.certified.unwrap().rmse_upper() > p.rmse);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationReport {
    /// One entry per parameter.
    pub parameters: Vec<ParameterReport>,
    /// Theorem 1 for the whole vector: E||theta - f(D)||^2 <= mse + gamma
    /// with probability at least 1 - delta, sigma = squared box diagonal.
    pub total: HoeffdingBound,
    /// The betting certificate for the whole vector at the same confidence
    /// `1 - delta` (absent in reports read from estimator files before
    /// format version 4).
    pub certified_total: Option<BettingBound>,
    /// The conformal intervals, if calibrated.
    pub intervals: Option<ConformalIntervals>,
}

impl ValidationReport {
    /// Build the report from truths and (box-clipped) estimates, r x q each.
    ///
    /// # Errors
    /// Shapes that disagree, no rows, estimates outside the box (the bound
    /// assumes clipping), or invalid `delta`.
    pub fn new(
        names: &[String],
        truth: ArrayView2<'_, f64>,
        estimates: ArrayView2<'_, f64>,
        lower: &[f64],
        upper: &[f64],
        delta: f64,
        intervals: Option<ConformalIntervals>,
    ) -> Result<Self> {
        let q = names.len();
        if truth.dim() != estimates.dim()
            || truth.ncols() != q
            || lower.len() != q
            || upper.len() != q
        {
            return Err(ValidateError::InvalidErrors(format!(
                "shapes disagree: truth {:?}, estimates {:?}, {q} names, box of {} and {}",
                truth.dim(),
                estimates.dim(),
                lower.len(),
                upper.len()
            )));
        }
        let r = truth.nrows();
        let totals: Vec<f64> = truth
            .rows()
            .into_iter()
            .zip(estimates.rows())
            .map(|(t, e)| t.iter().zip(e.iter()).map(|(a, b)| (a - b).powi(2)).sum())
            .collect();
        let sigma = squared_error_bound(lower, upper);
        let total = HoeffdingBound::from_squared_errors(&totals, sigma, delta)?;
        let certified_total = BettingBound::from_squared_errors(&totals, sigma, delta)?;
        let coverage = intervals.as_ref().map(|c| c.coverage(truth, estimates));
        let mut parameters = Vec::with_capacity(q);
        for j in 0..q {
            let (t, e) = (truth.column(j), estimates.column(j));
            let errors: Vec<f64> = e.iter().zip(t.iter()).map(|(a, b)| a - b).collect();
            let squared: Vec<f64> = errors.iter().map(|v| v * v).collect();
            let sigma = (upper[j] - lower[j]).powi(2);
            let hoeffding = HoeffdingBound::from_squared_errors(&squared, sigma, delta / q as f64)?;
            let certified = BettingBound::from_squared_errors(&squared, sigma, delta / q as f64)?;
            let mse = hoeffding.empirical_mse;
            let mean_t = t.sum() / r as f64;
            let var_t = t.iter().map(|v| (v - mean_t).powi(2)).sum::<f64>() / r as f64;
            parameters.push(ParameterReport {
                name: names[j].clone(),
                mse,
                rmse: mse.sqrt(),
                bias: errors.iter().sum::<f64>() / r as f64,
                r2: if var_t > 0.0 {
                    1.0 - mse / var_t
                } else {
                    f64::NAN
                },
                max_abs_error: errors.iter().fold(0.0f64, |m, v| m.max(v.abs())),
                hoeffding,
                certified: Some(certified),
                interval_half_width: intervals.as_ref().map(|c| c.half_widths()[j]),
                interval_coverage: coverage.as_ref().map(|c| c[j]),
            });
        }
        Ok(Self {
            parameters,
            total,
            certified_total: Some(certified_total),
            intervals,
        })
    }

    /// The certified bounds beside the errors they certify: each
    /// parameter's, then the whole vector's, as (bound, observed mean
    /// squared error); `None` for a report without betting certificates.
    fn certified_pairs(&self) -> Option<Vec<(BettingBound, f64)>> {
        self.parameters
            .iter()
            .map(|p| p.certified.map(|c| (c, p.mse)))
            .chain([self.certified_total.map(|c| (c, self.total.empirical_mse))])
            .collect()
    }

    /// The largest ratio of a certified RMSE to the observed one, over the
    /// parameters and the whole vector: how far the certificate a user
    /// reads sits above what was seen. Infinite where an observed error is
    /// 0 (no finite r certifies a perfect estimator) or the report has no
    /// betting certificate.
    ///
    /// ```
    /// use ndarray::array;
    /// use twostage_validate::ValidationReport;
    /// let truth = array![[0.1], [0.5], [-0.3], [0.8]];
    /// let estimate = array![[0.12], [0.45], [-0.3], [0.83]];
    /// let report = ValidationReport::new(&["theta".into()], truth.view(), estimate.view(), &[-0.9], &[0.9], 1e-3, None)?;
    /// let p = &report.parameters[0];
    /// let ratio = p.certified.unwrap().rmse_upper() / p.rmse;
    /// assert!(report.certified_ratio() >= ratio && ratio > 1.0);
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    pub fn certified_ratio(&self) -> f64 {
        let Some(pairs) = self.certified_pairs() else {
            return f64::INFINITY;
        };
        pairs
            .into_iter()
            .map(|(bound, mse)| {
                if mse > 0.0 {
                    (bound.upper() / mse).sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .fold(0.0, f64::max)
    }

    /// About how many records a validation of errors like these needs for
    /// every certified RMSE to be within `k` times the observed one. The
    /// betting bound's margin above the observed mean shrinks like `1/r`
    /// once the errors are small against their bound `sigma` (its floor,
    /// `sigma ln(1/delta) / (c r)`, is what a rare large error could
    /// hide), so the margin seen at r is scaled to the one `k` allows.
    /// Where the margin still shrinks like `1/sqrt(r)` the prediction falls
    /// short, and a grown run takes another round. `None` where no r
    /// would do: an observed error of 0, or no betting certificate.
    ///
    /// ```
    /// use ndarray::Array2;
    /// use twostage_validate::ValidationReport;
    /// // Small steady errors against a wide box: the certificate is loose
    /// // at 1000 records and the prediction asks for many more.
    /// let truth = Array2::from_shape_fn((1000, 1), |(i, _)| ((i * 37) % 100) as f64 / 120.0);
    /// let estimate = Array2::from_shape_fn((1000, 1), |(i, _)| truth[[i, 0]] + 0.02 * ((i % 5) as f64 - 2.0));
    /// let report = ValidationReport::new(&["theta".into()], truth.view(), estimate.view(), &[-0.9], &[0.9], 1e-3, None)?;
    /// assert!(report.certified_ratio() > 1.2);
    /// assert!(report.records_for_ratio(1.2).unwrap() > 10_000);
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    pub fn records_for_ratio(&self, k: f64) -> Option<u64> {
        let r = self.total.r as f64;
        let allowed = k * k - 1.0;
        let mut most = 0.0f64;
        for (bound, mse) in self.certified_pairs()? {
            if !(mse > 0.0 && allowed > 0.0) {
                return None;
            }
            let margin = bound.upper() - mse;
            most = most.max(r * margin / (allowed * mse));
        }
        // Beyond u64 no run could go: the caller's maximum ends it first.
        Some(most.ceil().min(u64::MAX as f64) as u64)
    }

    /// The size of the next round of a validation grown until every
    /// certified RMSE is within `k` times the observed one, at most
    /// `most` records: a tenth above the predicted need
    /// ([`Self::records_for_ratio`], which falls short where the margin
    /// still shrinks like `1/sqrt(r)`), at least a tenth above the records
    /// run and at most sixteen times them (a first round too small to
    /// predict from does not jump to the maximum).
    ///
    /// ```
    /// use ndarray::Array2;
    /// use twostage_validate::ValidationReport;
    /// let truth = Array2::from_shape_fn((1000, 1), |(i, _)| ((i * 37) % 100) as f64 / 120.0);
    /// let estimate = Array2::from_shape_fn((1000, 1), |(i, _)| truth[[i, 0]] + 0.02 * ((i % 5) as f64 - 2.0));
    /// let report = ValidationReport::new(&["theta".into()], truth.view(), estimate.view(), &[-0.9], &[0.9], 1e-3, None)?;
    /// let next = report.next_round(1.2, 1_000_000);
    /// let predicted = report.records_for_ratio(1.2).unwrap() as usize;
    /// assert_eq!(next, (predicted + predicted.div_ceil(10)).clamp(1100, 16_000));
    /// assert_eq!(report.next_round(1.2, 1200), 1200);
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    pub fn next_round(&self, k: f64, most: usize) -> usize {
        let r = usize::try_from(self.total.r).unwrap_or(usize::MAX);
        let (least, largest) = (r.saturating_add(r.div_ceil(10)), r.saturating_mul(16));
        let predicted = self
            .records_for_ratio(k)
            .and_then(|n| usize::try_from(n).ok())
            .map_or(largest, |n| n.saturating_add(n.div_ceil(10)));
        predicted.clamp(least, largest).min(most)
    }
}

impl std::fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "validation on r = {} records unseen in training (confidence 1 - delta = {}):",
            self.total.r,
            1.0 - self.total.delta
        )?;
        for p in &self.parameters {
            write!(
                f,
                "  {:<6} RMSE {:.4e}  bias {:+.2e}  R^2 {:.4}  max |err| {:.3e}",
                p.name, p.rmse, p.bias, p.r2, p.max_abs_error,
            )?;
            if let (Some(w), Some(c)) = (p.interval_half_width, p.interval_coverage) {
                write!(f, "  interval +-{w:.3e} (covers {:.1}%)", 100.0 * c)?;
            }
            writeln!(f)?;
        }
        writeln!(
            f,
            "  certified with probability >= {} (each parameter at delta / q, so all hold together):",
            1.0 - self.total.delta
        )?;
        for p in &self.parameters {
            match p.certified {
                Some(c) => write!(
                    f,
                    "    {:<6} RMSE <= {:.4e}  E[err^2] <= {:.3e} (betting)",
                    p.name,
                    c.rmse_upper(),
                    c.upper()
                )?,
                None => write!(f, "    {:<6} (no betting certificate in this file)", p.name)?,
            }
            writeln!(f, "  Theorem 1: E[err^2] <= {:.3e}", p.hoeffding.upper())?;
        }
        if let Some(c) = self.certified_total {
            write!(
                f,
                "  whole vector: E||theta - f(D)||^2 <= {:.4e} (betting); ",
                c.upper()
            )?;
        } else {
            write!(f, "  whole vector: ")?;
        }
        write!(
            f,
            "Theorem 1: <= {:.4e} + gamma {:.4e} = {:.4e}",
            self.total.empirical_mse,
            self.total.gamma,
            self.total.upper()
        )
    }
}

/// A grown validation's rounds as a note says them: "1000, 15000".
///
/// ```
/// assert_eq!(twostage_validate::rounds_listed(&[1000, 15000]), "1000, 15000");
/// ```
pub fn rounds_listed(rounds: &[usize]) -> String {
    rounds
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// A record's error of an estimator with an RMSE near `scale`, from a
    /// fixed uniform sequence (Weyl's, irrational step): i.i.d. enough for
    /// a bound, and the same on every machine.
    fn errors(r: usize, scale: f64) -> (Array2<f64>, Array2<f64>) {
        let step = (5.0f64.sqrt() - 1.0) / 2.0;
        let uniform = |i: usize| (i as f64 * step).fract();
        let truth = Array2::from_shape_fn((r, 2), |(i, j)| 1.6 * uniform(2 * i + j) - 0.8);
        // A centred uniform of width w has RMSE w / sqrt(12).
        let width = scale * 12f64.sqrt();
        let estimate = Array2::from_shape_fn((r, 2), |(i, j)| {
            let e = width * (uniform(7 * i + 3 * j + 1_000_003) - 0.5);
            (truth[[i, j]] + e).clamp(-0.9, 0.9)
        });
        (truth, estimate)
    }

    fn report(r: usize, scale: f64) -> ValidationReport {
        let (truth, estimate) = errors(r, scale);
        let names = ["a".to_string(), "b".to_string()];
        ValidationReport::new(
            &names,
            truth.view(),
            estimate.view(),
            &[-0.9, -0.9],
            &[0.9, 0.9],
            1e-3,
            None,
        )
        .unwrap()
    }

    /// The ratio is read off the report's own certificates, a second way.
    #[test]
    fn the_ratio_is_the_largest_certified_over_observed_rmse() {
        let report = report(1000, 0.03);
        let by_hand = report
            .parameters
            .iter()
            .map(|p| p.certified.unwrap().rmse_upper() / p.rmse)
            .chain([(report.certified_total.unwrap().upper() / report.total.empirical_mse).sqrt()])
            .fold(0.0, f64::max);
        assert!((report.certified_ratio() - by_hand).abs() < 1e-12);
    }

    /// Where the errors are small against their bound, the records
    /// predicted from a first round of 1000 bring the ratio to the target
    /// when the run is redone at that size: within 0.05 of it, where the
    /// first round sat far above.
    #[test]
    fn the_predicted_records_meet_the_target_when_run() {
        for (scale, k) in [(0.03, 1.2), (0.05, 1.5), (0.1, 1.3)] {
            let first = report(1000, scale);
            assert!(
                first.certified_ratio() > k + 0.3,
                "{scale}: {}",
                first.certified_ratio()
            );
            let n = usize::try_from(first.records_for_ratio(k).unwrap()).unwrap();
            let grown = report(n, scale).certified_ratio();
            assert!(
                (grown - k).abs() < 0.05,
                "{scale}, {k}: {n} records give {grown}"
            );
            let short = report(n / 2, scale).certified_ratio();
            assert!(
                short > k,
                "{scale}, {k}: half of {n} records already give {short}"
            );
        }
    }

    /// No r certifies an estimator that made no error, and no r meets a
    /// target of 1 or less: the prediction says so instead of a number.
    #[test]
    fn an_unreachable_target_predicts_nothing() {
        let truth = Array2::from_shape_fn((50, 1), |(i, _)| i as f64 / 100.0);
        let names = ["a".to_string()];
        let exact = ValidationReport::new(
            &names,
            truth.view(),
            truth.view(),
            &[-1.0],
            &[1.0],
            1e-3,
            None,
        )
        .unwrap();
        assert_eq!(exact.records_for_ratio(1.2), None);
        assert!(exact.certified_ratio().is_infinite());
        assert_eq!(exact.next_round(1.2, 10_000), 800);
        assert_eq!(report(1000, 0.03).records_for_ratio(1.0), None);
    }
}
