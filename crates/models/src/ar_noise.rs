//! Stationary autoregressive noise: fitted to a series (the residuals of a
//! fit, a measured residual) by Yule-Walker with the order chosen by BIC,
//! its autocovariances, and sample paths from an experiment's stream. One
//! model for the refined interval's noise and a model
//! file's coloured output noise.

use rand_distr::{Distribution, StandardNormal};

use crate::rng::ExperimentRng;

/// `e_k = a_1 e_(k-1) + ... + a_p e_(k-p) + s z_k`, stationary, of
/// variance `variance`.
#[derive(Debug, Clone, PartialEq)]
pub struct ArNoise {
    coefficients: Vec<f64>,
    /// The innovations' standard deviation `s`.
    innovation_sd: f64,
    /// The process's standard deviation.
    sd: f64,
    /// The process variance.
    variance: f64,
    /// The sample autocovariances up to the order (scaled as the variance),
    /// which the Yule-Walker model reproduces.
    leading: Vec<f64>,
}

impl ArNoise {
    /// White noise of standard deviation `sd`.
    pub fn white(sd: f64) -> Self {
        Self::ar1(0.0, sd)
    }

    /// AR(1) of coefficient `a` (|a| < 1) and stationary sd `sd`.
    pub fn ar1(a: f64, sd: f64) -> Self {
        let variance = sd * sd;
        let (coefficients, leading) = if a == 0.0 {
            (Vec::new(), vec![variance])
        } else {
            (vec![a], vec![variance, a * variance])
        };
        Self {
            coefficients,
            // As written, so that white noise is `sd z` to the bit.
            innovation_sd: sd * (1.0 - a * a).sqrt(),
            sd,
            variance,
            leading,
        }
    }

    /// The model of `series` (taken as zero-mean: residuals), its order
    /// by the Bayesian information criterion up to `min(max_order, T/10)`,
    /// its coefficients by Yule-Walker (Levinson-Durbin, so stationary),
    /// its variance scaled by `T / (T - fitted)` for `fitted` parameters
    /// fitted to the series.
    ///
    /// ```
    /// use twostage_models::{ArNoise, experiment_rng};
    /// // A long AR(1) path of 0.8 is found again.
    /// let mut path = vec![0.0; 20000];
    /// ArNoise::ar1(0.8, 1.0).fill(&mut experiment_rng(1, 0), &mut path);
    /// let fitted = ArNoise::fit(&path, 20, 0);
    /// assert_eq!(fitted.order(), 1);
    /// assert!((fitted.coefficients()[0] - 0.8).abs() < 0.02);
    /// assert!((fitted.variance() - 1.0).abs() < 0.1);
    /// ```
    pub fn fit(series: &[f64], max_order: usize, fitted: usize) -> Self {
        let t = series.len();
        let most = (t / 10).min(max_order);
        // Biased sample autocovariances: a positive definite Toeplitz
        // matrix, so the Yule-Walker model is stationary.
        let sample: Vec<f64> = (0..=most)
            .map(|lag| {
                series[lag..]
                    .iter()
                    .zip(series)
                    .map(|(x, y)| x * y)
                    .sum::<f64>()
                    / t.max(1) as f64
            })
            .collect();
        let correction = t as f64 / t.saturating_sub(fitted).max(1) as f64;
        let variance = sample[0] * correction;
        if variance.is_nan() || variance <= 0.0 || variance.is_infinite() {
            return Self::white(0.0);
        }
        // Levinson-Durbin, keeping the order of least BIC.
        let mut coefficients: Vec<f64> = Vec::new();
        let mut innovation = sample[0];
        let mut best = (t as f64 * innovation.ln(), Vec::new(), innovation);
        for p in 1..=most {
            let reflection = (sample[p]
                - coefficients
                    .iter()
                    .enumerate()
                    .map(|(i, a)| a * sample[p - 1 - i])
                    .sum::<f64>())
                / innovation;
            if !reflection.is_finite() || reflection.abs() >= 1.0 {
                break;
            }
            let previous = coefficients.clone();
            coefficients.push(reflection);
            for i in 0..p - 1 {
                coefficients[i] = previous[i] - reflection * previous[p - 2 - i];
            }
            innovation *= 1.0 - reflection * reflection;
            if innovation <= 0.0 {
                break;
            }
            let criterion = t as f64 * innovation.ln() + p as f64 * (t as f64).ln();
            if criterion < best.0 {
                best = (criterion, coefficients.clone(), innovation);
            }
        }
        let (_, coefficients, innovation) = best;
        let order = coefficients.len();
        Self {
            innovation_sd: (innovation * correction).sqrt(),
            sd: variance.sqrt(),
            variance,
            leading: sample[..=order].iter().map(|g| g * correction).collect(),
            coefficients,
        }
    }

    /// The order `p` (0: white).
    pub fn order(&self) -> usize {
        self.coefficients.len()
    }

    /// The coefficients `a_1 .. a_p`.
    pub fn coefficients(&self) -> &[f64] {
        &self.coefficients
    }

    /// The process variance.
    pub fn variance(&self) -> f64 {
        self.variance
    }

    /// The autocovariances from lag 0, at most `longest` of them, ending
    /// where they have died out (below 1e-9 of the variance).
    pub fn autocovariances(&self, longest: usize) -> Vec<f64> {
        let mut gamma = self.leading.clone();
        gamma.truncate(longest.max(1));
        while self.order() > 0 && gamma.len() < longest {
            let lag = gamma.len();
            let next: f64 = self
                .coefficients
                .iter()
                .enumerate()
                .map(|(i, a)| a * gamma[lag - 1 - i])
                .sum();
            gamma.push(next);
            if next.abs() < 1e-9 * self.variance {
                break;
            }
        }
        gamma
    }

    /// A sample path into `out`, from `rng`: stationary from its first
    /// sample for orders 0 and 1 (`e_0` of the process variance), after a
    /// burn-in of `50 (p + 1)` draws for higher orders.
    pub fn fill(&self, rng: &mut ExperimentRng, out: &mut [f64]) {
        let (sd, innovation) = (self.sd, self.innovation_sd);
        let p = self.order();
        if p <= 1 {
            let a = self.coefficients.first().copied().unwrap_or(0.0);
            let mut e = 0.0;
            for (k, v) in out.iter_mut().enumerate() {
                let z: f64 = StandardNormal.sample(rng);
                e = if k == 0 {
                    sd * z
                } else {
                    a * e + innovation * z
                };
                *v = e;
            }
            return;
        }
        let burn_in = 50 * (p + 1);
        let mut past = vec![0.0; p];
        for k in 0..burn_in + out.len() {
            let z: f64 = StandardNormal.sample(rng);
            let e = self
                .coefficients
                .iter()
                .zip(past.iter().rev())
                .map(|(a, e)| a * e)
                .sum::<f64>()
                + innovation * z;
            past.remove(0);
            past.push(e);
            if k >= burn_in {
                out[k - burn_in] = e;
            }
        }
    }
}
