//! A certificate that reads the errors it certifies: an upper confidence
//! bound on the expected squared error by betting (Waudby-Smith and Ramdas,
//! "Estimating means of bounded random variables by betting", JRSS B 86(1),
//! 2024, Section 3 and eq. (27)).
//!
//! Theorem 1 only knows that a squared error lies in `[0, sigma]`, so its
//! margin `gamma = sigma sqrt(ln(1/delta) / 2r)` is the same whether the
//! errors are large or tiny. Here a gambler bets, record after record,
//! that the mean squared error is below `m`; if it were not, her wealth
//! would be a nonnegative martingale, and by Ville's inequality it exceeds
//! `1/delta` with probability at most `delta`, at any time. The bound is
//! the smallest `m` that made her rich. When the errors are small and
//! steady she bets boldly and wins fast, so the margin shrinks like
//! `sigma ln(1/delta) / (c r)` instead of `sigma / sqrt(r)`.
//!
//! Because the bound is a confidence *sequence*, it holds at every r at
//! once: simulating until it is tight enough, and stopping then, keeps its
//! confidence (this is what `validate --target-rmse` does).

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::hoeffding::{check_delta, check_squared_errors};

/// The largest fraction of her wealth the gambler stakes on one record
/// (Waudby-Smith and Ramdas's truncation `c`; they suggest 1/2 or 3/4).
/// It caps how fast small errors can shrink the margin, to about
/// `sigma ln(1/delta) / (c r)`, and keeps every factor of the wealth at
/// least `1 - c`.
pub const MAX_STAKE: f64 = 0.75;

/// An upper bound on the expected squared error `E||theta - f(D)||^2`
/// that holds with probability at least `1 - delta`, from r fresh
/// validation simulations whose squared errors lie in `[0, sigma]`.
///
/// ```
/// use twostage_validate::{BettingBound, HoeffdingBound};
/// // Small, steady errors: the betting bound is close to them, Theorem 1
/// // is not.
/// let errors: Vec<f64> = (0..100_000).map(|i| 1e-3 * (1.0 + (i % 7) as f64 / 7.0)).collect();
/// let betting = BettingBound::from_squared_errors(&errors, 3.24, 1e-3)?;
/// let hoeffding = HoeffdingBound::from_squared_errors(&errors, 3.24, 1e-3)?;
/// assert!(betting.upper() < 2.0 * betting.empirical_mse);
/// assert!(hoeffding.upper() > 10.0 * hoeffding.empirical_mse);
/// // The same bound, stated for the root mean squared error.
/// assert!((betting.rmse_upper() - betting.upper().sqrt()).abs() < 1e-15);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BettingBound {
    /// The empirical mean squared error over the r validation simulations.
    pub empirical_mse: f64,
    /// The certified bound on the expected squared error.
    pub mse_bound: f64,
    /// The confidence parameter: the bound holds with probability >= 1 - delta.
    pub delta: f64,
    /// The number of validation simulations.
    pub r: u64,
    /// The assumed bound on each squared error.
    pub sigma: f64,
}

impl BettingBound {
    /// The betting bound on the mean of `squared_errors`, taken in the
    /// order given (the bets are predictable: each depends only on the
    /// errors before it), each at most `sigma`.
    ///
    /// # Errors
    /// Empty input, a non-finite or negative error, an error above `sigma`,
    /// or invalid `sigma` or `delta`.
    pub fn from_squared_errors(squared_errors: &[f64], sigma: f64, delta: f64) -> Result<Self> {
        check_squared_errors(squared_errors, sigma)?;
        check_delta(delta)?;
        let r = squared_errors.len();
        let empirical_mse = squared_errors.iter().sum::<f64>() / r as f64;
        let scaled: Vec<f64> = squared_errors.iter().map(|z| z / sigma).collect();
        let stakes = stakes(&scaled, delta);
        let bound = smallest_winning_mean(&scaled, &stakes, (1.0 / delta).ln());
        Ok(Self {
            empirical_mse,
            // Never below the observed mean: rounding in the last bisection
            // step must not make the statement claim less than was seen.
            mse_bound: (bound * sigma).max(empirical_mse),
            delta,
            r: r as u64,
            sigma,
        })
    }

    /// The certified bound on the expected squared error.
    pub fn upper(&self) -> f64 {
        self.mse_bound
    }

    /// The same bound on the root mean squared error, `sqrt(upper())`.
    pub fn rmse_upper(&self) -> f64 {
        self.mse_bound.sqrt()
    }
}

/// The predictable plug-in stakes of Waudby-Smith and Ramdas (their eq.
/// (27), one-sided): `lambda_t = min(sqrt(2 ln(1/delta) / (v_{t-1} t
/// ln(1 + t))), MAX_STAKE)`, where `v_{t-1}` is a regularized variance of
/// the values before t. The `t ln(1 + t)` makes the bound hold at every t.
fn stakes(values: &[f64], delta: f64) -> Vec<f64> {
    let log_inverse_delta = (1.0 / delta).ln();
    let mut stakes = Vec::with_capacity(values.len());
    // Regularized running mean and variance: a pseudo-observation of mean
    // 1/2 and variance 1/4 keeps the first stakes finite.
    let (mut sum, mut spread) = (0.5, 0.25);
    for (i, &x) in values.iter().enumerate() {
        let t = (i + 1) as f64;
        let variance = spread / t;
        let stake = (2.0 * log_inverse_delta / (variance * t * (1.0 + t).ln())).sqrt();
        stakes.push(stake.min(MAX_STAKE));
        sum += x;
        let mean = sum / (t + 1.0);
        spread += (x - mean) * (x - mean);
    }
    stakes
}

/// The gambler's log wealth after betting, with `stakes`, that the mean of
/// `values` is below `m`: `sum ln(1 + lambda_t (m - x_t))`, increasing in m.
fn log_wealth(values: &[f64], stakes: &[f64], m: f64) -> f64 {
    values
        .iter()
        .zip(stakes)
        .map(|(x, stake)| (stake * (m - x)).ln_1p())
        .sum()
}

/// The smallest `m` in `[0, 1]` whose log wealth reaches `target`, rounded
/// up (the bracket's upper end, so the bound errs on the safe side); 1 if
/// none does.
fn smallest_winning_mean(values: &[f64], stakes: &[f64], target: f64) -> f64 {
    // At m = 0 every factor is at most 1, so the wealth is below 1/delta.
    let (mut low, mut high) = (0.0f64, 1.0f64);
    if log_wealth(values, stakes, high) < target {
        return 1.0;
    }
    // 64 halvings of [0, 1] leave a bracket of 5e-20, far below any bound
    // a double can state about a mean of at least 0.
    for _ in 0..64 {
        let middle = 0.5 * (low + high);
        if middle <= low || middle >= high {
            break;
        }
        if log_wealth(values, stakes, middle) >= target {
            high = middle;
        } else {
            low = middle;
        }
    }
    high
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{HoeffdingBound, InvalidSetting};

    #[test]
    fn one_record_solves_its_single_bet_by_hand() {
        // One value x: the stake is MAX_STAKE (the prior variance 1/4 asks
        // for more), so the wealth 1 + c (m - x) reaches 1/delta at
        // m = x + (1/delta - 1) / c.
        let (x, delta, sigma) = (0.2, 0.9, 2.0);
        let bound = BettingBound::from_squared_errors(&[x * sigma], sigma, delta).unwrap();
        let by_hand = x + (1.0 / delta - 1.0) / MAX_STAKE;
        assert!((bound.upper() / sigma - by_hand).abs() < 1e-15);
        // At delta = 0.1 one record cannot win 10 times its stake: the
        // bound is the whole range.
        let trivial = BettingBound::from_squared_errors(&[x * sigma], sigma, 0.1).unwrap();
        assert_eq!(trivial.upper().to_bits(), sigma.to_bits());
    }

    #[test]
    fn stakes_follow_the_plug_in_formula() {
        // Two values, by hand: before the first, mean 1/2 and variance 1/4;
        // before the second, mean (1/2 + x1) / 2 and variance
        // (1/4 + (x1 - mean)^2) / 2.
        let (x1, delta) = (0.1, 0.05);
        let s = stakes(&[x1, 0.3], delta);
        let l = (1.0f64 / delta).ln();
        let first = (2.0 * l / (0.25 * 2f64.ln())).sqrt().min(MAX_STAKE);
        let mean = (0.5 + x1) / 2.0;
        let variance = (0.25 + (x1 - mean).powi(2)) / 2.0;
        let second = (2.0 * l / (variance * 2.0 * 3f64.ln()))
            .sqrt()
            .min(MAX_STAKE);
        assert!((s[0] - first).abs() < 1e-15 && (s[1] - second).abs() < 1e-15);
    }

    #[test]
    fn the_bound_is_where_the_wealth_reaches_one_over_delta() {
        let mut uniform = crate::tests::uniform_stream(7);
        let values: Vec<f64> = (0..500).map(|_| 0.01 * uniform()).collect();
        let delta = 1e-3;
        let bound = BettingBound::from_squared_errors(&values, 1.0, delta).unwrap();
        let s = stakes(&values, delta);
        let target = (1.0 / delta).ln();
        // A second, independent evaluation of the wealth: the product of
        // the factors, not the sum of their logarithms.
        let wealth = |m: f64| -> f64 {
            values
                .iter()
                .zip(&s)
                .map(|(x, l)| 1.0 + l * (m - x))
                .product()
        };
        assert!(wealth(bound.upper()).ln() >= target - 1e-9);
        assert!(wealth(bound.upper() * (1.0 - 1e-9)).ln() < target);
    }

    #[test]
    fn coverage_is_at_least_the_nominal_confidence() {
        // Repeated synthetic draws with known means, including the hardest
        // case for a bound that trusts small variance: rare large errors.
        let mut uniform = crate::tests::uniform_stream(2024);
        let delta = 0.1;
        let trials = 2000;
        type Draw = fn(f64) -> f64;
        let cases: [(&str, Draw, f64); 4] = [
            ("uniform", |u| u, 0.5),
            ("u^4", |u| u.powi(4), 0.2),
            ("rare ones", |u| if u < 0.02 { 1.0 } else { 0.0 }, 0.02),
            ("small steady", |u| 1e-3 * (1.0 + u), 1.5e-3),
        ];
        for (name, draw, mean) in cases {
            for r in [20usize, 200] {
                let mut misses = 0;
                for _ in 0..trials {
                    let values: Vec<f64> = (0..r).map(|_| draw(uniform())).collect();
                    let bound = BettingBound::from_squared_errors(&values, 1.0, delta).unwrap();
                    if bound.upper() < mean {
                        misses += 1;
                    }
                }
                // The miss rate may exceed delta only by sampling noise:
                // three binomial standard deviations.
                let allowed = delta + 3.0 * (delta * (1.0 - delta) / trials as f64).sqrt();
                let rate = misses as f64 / trials as f64;
                assert!(rate <= allowed, "{name}, r = {r}: missed {rate}");
            }
        }
    }

    #[test]
    fn small_steady_errors_cost_about_sigma_ln_over_c_r() {
        // The margin the benchmark's validation relies on: with errors
        // far below sigma, about sigma ln(1/delta) / (c r), not Hoeffding's
        // sigma sqrt(ln(1/delta) / 2r).
        let mut uniform = crate::tests::uniform_stream(99);
        let (sigma, delta, r) = (3.24, 1e-3, 100_000);
        let errors: Vec<f64> = (0..r).map(|_| 7e-4 * 2.0 * uniform()).collect();
        let betting = BettingBound::from_squared_errors(&errors, sigma, delta).unwrap();
        let margin = betting.upper() - betting.empirical_mse;
        let predicted = sigma * (1.0 / delta).ln() / (MAX_STAKE * r as f64);
        assert!(
            margin > predicted && margin < 1.1 * predicted,
            "margin {margin}, predicted {predicted}"
        );
        let hoeffding = HoeffdingBound::from_squared_errors(&errors, sigma, delta).unwrap();
        assert!(hoeffding.gamma > 30.0 * margin);
    }

    #[test]
    fn bad_input_is_refused() {
        use crate::ValidateError;
        let refused = |errors: &[f64], sigma: f64, delta: f64| {
            BettingBound::from_squared_errors(errors, sigma, delta)
                .expect_err("bad input is refused")
        };
        assert!(matches!(
            refused(&[], 1.0, 0.1),
            ValidateError::InvalidErrors(m) if m.contains("no validation errors")
        ));
        assert!(matches!(
            refused(&[0.1, f64::NAN], 1.0, 0.1),
            ValidateError::InvalidErrors(m) if m.contains("squared error 1 is NaN")
        ));
        assert!(matches!(
            refused(&[0.1, 2.0], 1.0, 0.1),
            ValidateError::AboveSigma { index: 1, .. }
        ));
        assert!(matches!(
            refused(&[0.1], 1.0, 0.0),
            ValidateError::InvalidSetting(InvalidSetting { name: "delta", .. })
        ));
        assert!(matches!(
            refused(&[0.1], 0.0, 0.1),
            ValidateError::InvalidSetting(InvalidSetting { name: "sigma", .. })
        ));
    }
}
