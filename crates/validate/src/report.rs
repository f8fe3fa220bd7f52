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
