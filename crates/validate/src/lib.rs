//! Validation of two-stage estimators.
//!
//! Because the two-stage estimator is trained on simulations, it can be
//! validated on fresh simulations at no cost in real experiments (Section
//! 4.3 of the paper). Theorem 1 (Hoeffding) turns the empirical mean squared
//! error over r such simulations into a bound on the true one:
//!
//! `E||theta - f(D)||^2 <= (1/r) sum ||theta_i - f(D_i)||^2 + gamma`
//! with probability at least `1 - delta`, whenever `r > sigma^2 / (2 gamma^2) ln(1/delta)`.
//!
//! Theorem 1 only uses that each squared error lies in `[0, sigma]`; the
//! betting certificate ([`BettingBound`]) also reads how small and steady
//! the errors are, and certifies close to the observed error once r is in
//! the tens of thousands, at the same confidence.
//!
//! Split-conformal intervals ([`ConformalIntervals`]) add a per-estimate
//! error bar, and [`ValidationReport`] gathers it all per parameter.
//!
//! # Example
//!
//! ```
//! use twostage_validate::{hoeffding_sample_size, squared_error_bound, HoeffdingBound};
//!
//! // Estimates clipped to the benchmark's box [-0.9, 0.9] err by at most 1.8.
//! let sigma = squared_error_bound(&[-0.9], &[0.9]);
//! let r = hoeffding_sample_size(sigma, 0.05, 1e-3)?;
//! assert_eq!(r, 14_503);
//! let squared_errors = vec![0.0009; r as usize];
//! let bound = HoeffdingBound::from_squared_errors(&squared_errors, sigma, 1e-3)?;
//! assert!(bound.gamma < 0.05 && bound.upper() < 0.051);
//! # Ok::<(), twostage_validate::ValidateError>(())
//! ```
#![deny(missing_docs)]

mod betting;
mod conformal;
mod error;
mod hoeffding;
mod posterior;
mod report;

pub use betting::{BettingBound, MAX_STAKE};
pub use conformal::ConformalIntervals;
pub use error::{InvalidSetting, Result, ValidateError};
pub use hoeffding::{HoeffdingBound, hoeffding_gamma, hoeffding_sample_size, squared_error_bound};
pub use posterior::{CALIBRATION_DRAWS, COVERAGE_LEVELS, PosteriorCalibration};
pub use report::{ParameterReport, ValidationReport, rounds_listed};

#[cfg(test)]
mod tests {
    /// Uniform draws in [0, 1) from a 64-bit LCG (Knuth's MMIX constants):
    /// enough for coverage tests, and keeps this crate free of a
    /// random-number dependency.
    pub(crate) fn uniform_stream(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }
}
