//! Theorem 1 of the paper (Hoeffding's inequality): how many validation
//! simulations make the empirical mean squared error a guaranteed bound.

use crate::InvalidSetting;
use serde::{Deserialize, Serialize};

use crate::error::{Result, ValidateError};

fn check_positive(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(InvalidSetting::new(name, value, "must be finite and > 0").into())
    }
}

pub(crate) fn check_delta(delta: f64) -> Result<()> {
    if delta > 0.0 && delta < 1.0 {
        Ok(())
    } else {
        Err(InvalidSetting::new("delta", delta, "must lie in (0, 1)").into())
    }
}

/// Squared errors a bound can take: at least one, each finite, in
/// `[0, sigma]`.
pub(crate) fn check_squared_errors(squared_errors: &[f64], sigma: f64) -> Result<()> {
    check_positive("sigma", sigma)?;
    if squared_errors.is_empty() {
        return Err(ValidateError::InvalidErrors(
            "no validation errors: run at least one validation simulation".into(),
        ));
    }
    for (index, &value) in squared_errors.iter().enumerate() {
        if !(value.is_finite() && value >= 0.0) {
            return Err(ValidateError::InvalidErrors(format!(
                "squared error {index} is {value}, not a finite non-negative number"
            )));
        }
        if value > sigma {
            return Err(ValidateError::AboveSigma {
                index,
                value,
                sigma,
            });
        }
    }
    Ok(())
}

/// The bound `sigma` on the squared error `||theta - f(D)||^2` when both the
/// true parameter and the estimate lie in the box `[lower, upper]`: the
/// squared diagonal of the box (the paper: "sigma can be easily computed
/// whenever theta takes value in a compact domain").
///
/// ```
/// use twostage_validate::squared_error_bound;
/// // The benchmark's box [-0.9, 0.9]: sigma = 1.8^2.
/// assert!((squared_error_bound(&[-0.9], &[0.9]) - 3.24).abs() < 1e-12);
/// ```
pub fn squared_error_bound(lower: &[f64], upper: &[f64]) -> f64 {
    lower
        .iter()
        .zip(upper)
        .map(|(lo, hi)| (hi - lo).powi(2))
        .sum()
}

/// The smallest number r of validation simulations with
/// `r > sigma^2 / (2 gamma^2) ln(1 / delta)`, eq. (4).
///
/// ```
/// use twostage_validate::hoeffding_sample_size;
/// // sigma = 3.24 (the benchmark box), gamma = 0.01, delta = 1e-3:
/// // 3.24^2 / 2e-4 * ln(1000) = 362,574.26..., so r = 362,575.
/// assert_eq!(hoeffding_sample_size(3.24, 0.01, 1e-3)?, 362_575);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
///
/// # Errors
/// [`ValidateError::InvalidSetting`] unless `sigma > 0`, `gamma > 0` and
/// `0 < delta < 1`, or if r would not fit in a `u64`.
pub fn hoeffding_sample_size(sigma: f64, gamma: f64, delta: f64) -> Result<u64> {
    check_positive("sigma", sigma)?;
    check_positive("gamma", gamma)?;
    check_delta(delta)?;
    let bound = sigma * sigma / (2.0 * gamma * gamma) * (1.0 / delta).ln();
    if bound >= u64::MAX as f64 {
        return Err(InvalidSetting::new(
            "gamma",
            gamma,
            "is so small that the sample size overflows: raise gamma or delta",
        )
        .into());
    }
    // The strict inequality: the next integer above the bound.
    Ok(bound.floor() as u64 + 1)
}

/// The accuracy gamma that r validation simulations guarantee: the
/// inversion of eq. (4), `gamma = sigma sqrt(ln(1 / delta) / (2 r))`.
///
/// ```
/// use twostage_validate::hoeffding_gamma;
/// let gamma = hoeffding_gamma(3.24, 0.001, 200)?;
/// assert!((gamma - 3.24 * (1000f64.ln() / 400.0).sqrt()).abs() < 1e-12);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
///
/// # Errors
/// [`ValidateError::InvalidSetting`] unless `sigma > 0`, `0 < delta < 1`
/// and `r >= 1`.
pub fn hoeffding_gamma(sigma: f64, delta: f64, r: u64) -> Result<f64> {
    check_positive("sigma", sigma)?;
    check_delta(delta)?;
    if r == 0 {
        return Err(
            InvalidSetting::new("r", 0.0, "needs at least one validation simulation").into(),
        );
    }
    Ok(sigma * ((1.0 / delta).ln() / (2.0 * r as f64)).sqrt())
}

/// The guarantee of Theorem 1 for one set of validation errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HoeffdingBound {
    /// The empirical mean squared error over the r validation simulations.
    pub empirical_mse: f64,
    /// The accuracy gamma guaranteed by r.
    pub gamma: f64,
    /// The confidence parameter: the bound holds with probability >= 1 - delta.
    pub delta: f64,
    /// The number of validation simulations.
    pub r: u64,
    /// The assumed bound on each squared error.
    pub sigma: f64,
}

impl HoeffdingBound {
    /// Theorem 1 applied to `squared_errors`, the values
    /// `||theta_i - f(D_i)||^2` of r fresh validation simulations, each at
    /// most `sigma`: with probability at least `1 - delta`,
    /// `E||theta - f(D)||^2 <= empirical_mse + gamma`.
    ///
    /// ```
    /// use twostage_validate::HoeffdingBound;
    /// let errors = vec![0.001; 400];
    /// let bound = HoeffdingBound::from_squared_errors(&errors, 3.24, 1e-3)?;
    /// assert!((bound.empirical_mse - 0.001).abs() < 1e-15);
    /// assert!(bound.upper() > bound.empirical_mse);
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    ///
    /// # Errors
    /// Empty input, a non-finite or negative error, an error above `sigma`
    /// (the theorem would not apply), or invalid `sigma` or `delta`.
    pub fn from_squared_errors(squared_errors: &[f64], sigma: f64, delta: f64) -> Result<Self> {
        check_squared_errors(squared_errors, sigma)?;
        let r = squared_errors.len() as u64;
        let empirical_mse = squared_errors.iter().sum::<f64>() / r as f64;
        Ok(Self {
            empirical_mse,
            gamma: hoeffding_gamma(sigma, delta, r)?,
            delta,
            r,
            sigma,
        })
    }

    /// The guaranteed bound on the expected squared error: `empirical_mse + gamma`.
    pub fn upper(&self) -> f64 {
        self.empirical_mse + self.gamma
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_size_and_gamma_invert_each_other() {
        for (sigma, gamma, delta) in [(3.24, 0.01, 1e-3), (240.0, 1.0, 0.05), (1.0, 0.1, 1e-9)] {
            let r = hoeffding_sample_size(sigma, gamma, delta).unwrap();
            // r is the first integer above the bound: r - 1 is not enough.
            assert!(hoeffding_gamma(sigma, delta, r).unwrap() < gamma);
            assert!(hoeffding_gamma(sigma, delta, r - 1).unwrap() >= gamma);
        }
    }

    #[test]
    fn hoeffding_holds_empirically_for_bounded_errors() {
        // Errors uniform on [0, sigma] (mean sigma / 2): over many repetitions
        // the bound may fail with frequency at most delta. A tiny LCG keeps
        // this crate free of a random-number dependency.
        let (sigma, delta, r) = (1.0, 0.1, 50u64);
        let mut uniform = crate::tests::uniform_stream(12345);
        let trials = 4000;
        let mut failures = 0;
        for _ in 0..trials {
            let errors: Vec<f64> = (0..r).map(|_| sigma * uniform()).collect();
            let bound = HoeffdingBound::from_squared_errors(&errors, sigma, delta).unwrap();
            if 0.5 > bound.upper() {
                failures += 1;
            }
        }
        // Hoeffding is conservative: the failure rate is far below delta.
        assert!(
            (failures as f64) / (trials as f64) <= delta,
            "{failures} failures"
        );
    }

    #[test]
    fn bad_settings_and_errors_are_rejected() {
        assert!(hoeffding_sample_size(0.0, 0.1, 0.1).is_err());
        assert!(hoeffding_sample_size(1.0, 0.0, 0.1).is_err());
        assert!(hoeffding_sample_size(1.0, 0.1, 1.0).is_err());
        assert!(hoeffding_sample_size(1.0, 1e-300, 0.1).is_err());
        assert!(HoeffdingBound::from_squared_errors(&[], 1.0, 0.1).is_err());
        assert!(HoeffdingBound::from_squared_errors(&[f64::NAN], 1.0, 0.1).is_err());
        let above = HoeffdingBound::from_squared_errors(&[0.1, 2.0], 1.0, 0.1).unwrap_err();
        assert!(matches!(above, ValidateError::AboveSigma { index: 1, .. }));
    }
}
