//! Bayes-optimal references: the posterior mean under the uniform prior is
//! the estimator with the least mean squared error, the limit no method can
//! beat on the same data.

use crate::InvalidSetting;
use rayon::prelude::*;
use twostage_models::IoData;

use crate::error::{BaselineError, Result};
use crate::kalman::benchmark_kalman;
use crate::{Estimate, RecordEstimator};

/// The benchmark's posterior of theta given one record.
#[derive(Debug, Clone, PartialEq)]
pub struct Posterior {
    /// Posterior mean (the Bayes estimate under squared error).
    pub mean: f64,
    /// Posterior standard deviation.
    pub sd: f64,
    /// The grid point of highest posterior density (MAP).
    pub map: f64,
    /// Grid points evaluated in all.
    pub points: usize,
    /// Refinement levels after the initial grid.
    pub levels: usize,
}

/// Settings of the benchmark posterior.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `initial_points` | 1801 (spacing 1e-3 on [-0.9, 0.9]) | >= 3 |
/// | `tolerance` | 1e-7 | > 0: refine until the mean moves less |
/// | `max_levels` | 8 | halvings of the spacing where the posterior has mass |
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BayesBenchmark {
    initial_points: usize,
    tolerance: f64,
    max_levels: usize,
}

impl Default for BayesBenchmark {
    fn default() -> Self {
        Self {
            initial_points: 1801,
            tolerance: 1e-7,
            max_levels: 8,
        }
    }
}

/// Posterior mass is ignored where the density is below this share of its peak.
const NEGLIGIBLE: f64 = 1e-14;

impl BayesBenchmark {
    /// Another initial grid size (coarser grids for tests).
    pub fn initial_points(mut self, points: usize) -> Self {
        self.initial_points = points;
        self
    }

    /// Another stopping tolerance on the posterior mean.
    pub fn tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = tolerance;
        self
    }

    /// The posterior of theta given `record`, from the exact likelihood
    /// (Kalman filter) on an adaptive grid: the trapezoid rule on the
    /// initial grid, then the spacing is halved in every interval with
    /// non-negligible mass until the mean moves less than the tolerance.
    ///
    /// # Errors
    /// A record the Kalman filter refuses, or invalid settings.
    pub fn posterior(&self, record: &IoData) -> Result<Posterior> {
        if self.initial_points < 3 || self.tolerance.is_nan() || self.tolerance <= 0.0 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "grid points and tolerance",
                value: format!("{} and {}", self.initial_points, self.tolerance),
                reason: "at least 3 points and a positive tolerance".into(),
            }));
        }
        let (lo, hi) = (-0.9, 0.9);
        let log_likelihood = |thetas: &[f64]| -> Result<Vec<f64>> {
            thetas
                .par_iter()
                .map(|&t| benchmark_kalman(t, record).map(|r| r.log_likelihood))
                .collect()
        };
        let step = (hi - lo) / (self.initial_points - 1) as f64;
        let mut grid: Vec<(f64, f64)> = {
            let thetas: Vec<f64> = (0..self.initial_points)
                .map(|i| lo + step * i as f64)
                .collect();
            let ll = log_likelihood(&thetas)?;
            thetas.into_iter().zip(ll).collect()
        };
        let mut previous = moments(&grid);
        let mut levels = 0;
        while levels < self.max_levels {
            levels += 1;
            let peak = grid.iter().fold(f64::NEG_INFINITY, |m, p| m.max(p.1));
            let threshold = peak + NEGLIGIBLE.ln();
            let midpoints: Vec<f64> = grid
                .windows(2)
                .filter(|w| w[0].1 > threshold || w[1].1 > threshold)
                .map(|w| 0.5 * (w[0].0 + w[1].0))
                .collect();
            let ll = log_likelihood(&midpoints)?;
            grid.extend(midpoints.into_iter().zip(ll));
            grid.sort_by(|a, b| a.0.total_cmp(&b.0));
            let current = moments(&grid);
            let moved = (current.0 - previous.0).abs();
            previous = current;
            if moved < self.tolerance {
                break;
            }
        }
        let (mean, sd, map) = previous;
        Ok(Posterior {
            mean,
            sd,
            map,
            points: grid.len(),
            levels,
        })
    }
}

/// Mean, standard deviation and mode of the density exp(ll) on a sorted
/// grid, by the trapezoid rule.
fn moments(grid: &[(f64, f64)]) -> (f64, f64, f64) {
    let (mut map, peak) = (
        grid[0].0,
        grid.iter().fold(f64::NEG_INFINITY, |m, p| m.max(p.1)),
    );
    for p in grid {
        if p.1 >= peak {
            map = p.0;
            break;
        }
    }
    let (mut mass, mut first, mut second) = (0.0, 0.0, 0.0);
    for w in grid.windows(2) {
        let (t0, t1) = (w[0].0, w[1].0);
        let (p0, p1) = ((w[0].1 - peak).exp(), (w[1].1 - peak).exp());
        let dt = t1 - t0;
        mass += 0.5 * dt * (p0 + p1);
        first += 0.5 * dt * (t0 * p0 + t1 * p1);
        second += 0.5 * dt * (t0 * t0 * p0 + t1 * t1 * p1);
    }
    let mean = first / mass;
    let variance = (second / mass - mean * mean).max(0.0);
    (mean, variance.sqrt(), map)
}

impl RecordEstimator for BayesBenchmark {
    fn name(&self) -> &str {
        "bayes"
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        let p = self.posterior(record)?;
        Ok(Estimate {
            theta: vec![p.mean],
            spread: Some(vec![p.sd]),
        })
    }
}
