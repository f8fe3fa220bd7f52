//! Extended and unscented Kalman filters on the augmented benchmark
//! (Section 5.1 of the paper).

// 3 x 3 matrix algebra reads best with indices.
#![allow(clippy::needless_range_loop)]

use twostage_models::IoData;

use crate::augmented::{
    InitialCovariance, M3, MEASUREMENT_VARIANCE, THETA_RANDOM_WALK_VARIANCE, add, cholesky, mul,
    process_noise, symmetrize, transition, transition_jacobian, transpose,
};
use crate::error::{BaselineError, Result};
use crate::kalman::benchmark_signals;
use crate::{Estimate, RecordEstimator};

/// What a filter run leaves: the final update and the innovation statistics.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterRun {
    /// State estimate after the last update, (x1, x2, theta).
    pub state: [f64; 3],
    /// Its covariance.
    pub covariance: [[f64; 3]; 3],
    /// Gaussian log-likelihood of the innovations.
    pub log_likelihood: f64,
    /// Sum of squared innovations.
    pub sum_squared_innovations: f64,
}

/// The measurement update with y = x2 + v (linear, shared by both filters).
fn update(z: &mut [f64; 3], p: &mut M3, y: f64, k: usize, run: &mut FilterRun) -> Result<()> {
    let s = p[1][1] + MEASUREMENT_VARIANCE;
    if s.is_nan() || s <= 0.0 {
        return Err(BaselineError::Numerical {
            sample: k,
            what: format!("innovation variance {s}"),
        });
    }
    let e = y - z[1];
    let gain = [p[0][1] / s, p[1][1] / s, p[2][1] / s];
    for i in 0..3 {
        z[i] += gain[i] * e;
    }
    let row = p[1];
    for i in 0..3 {
        for j in 0..3 {
            p[i][j] -= gain[i] * row[j];
        }
    }
    symmetrize(p);
    run.log_likelihood -= 0.5 * ((2.0 * std::f64::consts::PI * s).ln() + e * e / s);
    run.sum_squared_innovations += e * e;
    if !z.iter().all(|v| v.is_finite()) {
        return Err(BaselineError::Numerical {
            sample: k,
            what: "the state estimate diverged".into(),
        });
    }
    Ok(())
}

fn start(p0: &InitialCovariance, theta0: f64) -> ([f64; 3], M3, FilterRun) {
    let z = [0.0, 0.0, theta0];
    let p = p0.matrix();
    let run = FilterRun {
        state: z,
        covariance: p,
        log_likelihood: 0.0,
        sum_squared_innovations: 0.0,
    };
    (z, p, run)
}

/// Where a filter starts and how fast theta may wander.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterStart {
    /// P(0|-1).
    pub p0: InitialCovariance,
    /// theta_hat(0|-1); x_hat starts at 0, as x(0) = 0.
    pub theta0: f64,
    /// Variance of the random walk of theta (the paper: 1e-6).
    pub theta_walk: f64,
}

impl FilterStart {
    /// The paper's start: theta_hat = 0, random walk 1e-6, and `p0`.
    pub fn paper(p0: InitialCovariance) -> Self {
        Self {
            p0,
            theta0: 0.0,
            theta_walk: THETA_RANDOM_WALK_VARIANCE,
        }
    }
}

/// Run the EKF over a record from `x_hat(0|-1) = (0, 0, theta0)`, `P(0|-1) = P0`.
///
/// # Errors
/// A record that is not SISO or not finite, or a covariance that breaks down.
pub fn run_ekf(record: &IoData, start_at: &FilterStart) -> Result<FilterRun> {
    let (u, y) = benchmark_signals(record)?;
    let (mut z, mut p, mut run) = start(&start_at.p0, start_at.theta0);
    let q = process_noise(start_at.theta_walk);
    for (k, (&uk, &yk)) in u.iter().zip(y).enumerate() {
        update(&mut z, &mut p, yk, k, &mut run)?;
        run.state = z;
        run.covariance = p;
        let f = transition_jacobian(z, uk);
        z = transition(z, uk);
        p = add(&mul(&mul(&f, &p), &transpose(&f)), &q);
        symmetrize(&mut p);
    }
    Ok(run)
}

/// Scaled unscented transform parameters (Wan and van der Merwe, 2000).
///
/// | setting | default | meaning |
/// |---|---|---|
/// | `alpha` | 1 | spread of the sigma points around the mean |
/// | `beta` | 2 | prior knowledge of the distribution (2 is optimal for Gaussians) |
/// | `kappa` | 0 | secondary scaling |
///
/// With the defaults `lambda = alpha^2 (n + kappa) - n = 0`: the centre point
/// has mean weight 0 and the six others 1/6 each, all non-negative, which
/// keeps the covariance positive on this three-state problem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnscentedParams {
    /// Spread of the sigma points.
    pub alpha: f64,
    /// Distribution prior (2 for Gaussians).
    pub beta: f64,
    /// Secondary scaling.
    pub kappa: f64,
}

impl Default for UnscentedParams {
    fn default() -> Self {
        Self {
            alpha: 1.0,
            beta: 2.0,
            kappa: 0.0,
        }
    }
}

/// Run the UKF (additive noise) over a record, as [`run_ekf`].
///
/// # Errors
/// As [`run_ekf`]; also a covariance whose square root fails.
pub fn run_ukf(
    record: &IoData,
    start_at: &FilterStart,
    params: &UnscentedParams,
) -> Result<FilterRun> {
    let (u, y) = benchmark_signals(record)?;
    let (mut z, mut p, mut run) = start(&start_at.p0, start_at.theta0);
    let q = process_noise(start_at.theta_walk);
    let n = 3.0;
    let lambda = params.alpha * params.alpha * (n + params.kappa) - n;
    let wm0 = lambda / (n + lambda);
    let wc0 = wm0 + 1.0 - params.alpha * params.alpha + params.beta;
    let wi = 0.5 / (n + lambda);
    let spread = (n + lambda).sqrt();
    for (k, (&uk, &yk)) in u.iter().zip(y).enumerate() {
        update(&mut z, &mut p, yk, k, &mut run)?;
        run.state = z;
        run.covariance = p;
        let l = cholesky(&p).ok_or_else(|| BaselineError::Numerical {
            sample: k,
            what: "the state covariance lost positive definiteness".into(),
        })?;
        // Sigma points z, z +- spread * column j of L, through the transition.
        let mut points = [[0.0; 3]; 7];
        points[0] = transition(z, uk);
        for j in 0..3 {
            let mut plus = z;
            let mut minus = z;
            for i in 0..3 {
                plus[i] += spread * l[i][j];
                minus[i] -= spread * l[i][j];
            }
            points[1 + j] = transition(plus, uk);
            points[4 + j] = transition(minus, uk);
        }
        let mut mean = [0.0; 3];
        for i in 0..3 {
            mean[i] = wm0 * points[0][i] + wi * points[1..].iter().map(|s| s[i]).sum::<f64>();
        }
        let mut cov = q;
        for (s, point) in points.iter().enumerate() {
            let w = if s == 0 { wc0 } else { wi };
            for i in 0..3 {
                for j in 0..3 {
                    cov[i][j] += w * (point[i] - mean[i]) * (point[j] - mean[j]);
                }
            }
        }
        symmetrize(&mut cov);
        z = mean;
        p = cov;
    }
    Ok(run)
}

/// Which Kalman filter.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Extended,
    Unscented(UnscentedParams),
}

/// The EKF or UKF of the paper as a [`RecordEstimator`]: theta is the third
/// state after the last update, its spread the square root of its variance.
///
/// ```
/// use twostage_baselines::{InitialCovariance, KalmanEstimator, RecordEstimator};
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.1], &mut experiment_rng(2, 0), &mut record)?;
/// let ekf = KalmanEstimator::ekf(InitialCovariance::Eq6);
/// let estimate = ekf.estimate(&record)?;
/// assert!(estimate.theta[0].is_finite() && estimate.spread.is_some());
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanEstimator {
    kind: Kind,
    start: FilterStart,
    name: String,
}

impl KalmanEstimator {
    /// The EKF with initial covariance `p0` and theta_hat(0) = 0.
    pub fn ekf(p0: InitialCovariance) -> Self {
        Self {
            kind: Kind::Extended,
            start: FilterStart::paper(p0),
            name: "ekf".into(),
        }
    }

    /// The UKF with the default unscented parameters.
    pub fn ukf(p0: InitialCovariance) -> Self {
        Self::ukf_with(p0, UnscentedParams::default())
    }

    /// The UKF with given unscented parameters.
    pub fn ukf_with(p0: InitialCovariance, params: UnscentedParams) -> Self {
        Self {
            kind: Kind::Unscented(params),
            start: FilterStart::paper(p0),
            name: "ukf".into(),
        }
    }

    /// Start theta_hat at another value (the paper's footnote tried
    /// -0.8, -0.3, 0.3, 0.8).
    pub fn with_initial_theta(mut self, theta0: f64) -> Self {
        self.start.theta0 = theta0;
        self
    }

    /// Another random-walk variance of theta (the paper: 1e-6).
    pub fn with_theta_walk(mut self, variance: f64) -> Self {
        self.start.theta_walk = variance;
        self
    }

    /// Run the filter and return everything it computed.
    ///
    /// # Errors
    /// As [`run_ekf`].
    pub fn run(&self, record: &IoData) -> Result<FilterRun> {
        match self.kind {
            Kind::Extended => run_ekf(record, &self.start),
            Kind::Unscented(params) => run_ukf(record, &self.start, &params),
        }
    }
}

impl RecordEstimator for KalmanEstimator {
    fn name(&self) -> &str {
        &self.name
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        let run = self.run(record)?;
        Ok(Estimate {
            theta: vec![run.state[2]],
            spread: Some(vec![run.covariance[2][2].max(0.0).sqrt()]),
        })
    }
}
