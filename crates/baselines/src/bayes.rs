//! Bayes-optimal references: the posterior mean under the uniform prior is
//! the estimator with the least mean squared error, the limit no method can
//! beat on the same data.

use crate::InvalidSetting;
use rand::{Rng, RngExt};
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
        let (grid, levels) = self.grid(record)?;
        let (mean, sd, map) = moments(&grid);
        Ok(Posterior {
            mean,
            sd,
            map,
            points: grid.len(),
            levels,
        })
    }

    /// `count` independent draws of theta from the posterior given
    /// `record`: the density interpolated linearly between the adaptive
    /// grid's points (the trapezoid rule's density), drawn exactly from by
    /// inverting its distribution function; the reference a posterior's
    /// draws are tested against.
    ///
    /// # Errors
    /// As [`BayesBenchmark::posterior`].
    pub fn draws(&self, record: &IoData, count: usize, rng: &mut impl Rng) -> Result<Vec<f64>> {
        let (grid, _) = self.grid(record)?;
        let peak = grid.iter().fold(f64::NEG_INFINITY, |m, p| m.max(p.1));
        let density: Vec<f64> = grid.iter().map(|p| (p.1 - peak).exp()).collect();
        let cells: Vec<f64> = grid
            .windows(2)
            .zip(density.windows(2))
            .map(|(t, p)| 0.5 * (t[1].0 - t[0].0) * (p[0] + p[1]))
            .collect();
        let cumulative = running_sums(&cells);
        Ok((0..count)
            .map(|_| {
                let i = pick(&cumulative, rng.random());
                let s = linear_draw(density[i], density[i + 1], rng.random());
                grid[i].0 + s * (grid[i + 1].0 - grid[i].0)
            })
            .collect())
    }

    /// The adaptive grid of (theta, log-likelihood), sorted, and the
    /// levels of halving it took: the trapezoid rule on the initial grid,
    /// then the spacing halved in every interval with non-negligible mass
    /// until the mean moves less than the tolerance.
    fn grid(&self, record: &IoData) -> Result<(Vec<(f64, f64)>, usize)> {
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
        let mut previous = moments(&grid).0;
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
            let current = moments(&grid).0;
            let moved = (current - previous).abs();
            previous = current;
            if moved < self.tolerance {
                break;
            }
        }
        Ok((grid, levels))
    }
}

/// The running sums of `masses`, the first entry the first mass.
pub(crate) fn running_sums(masses: &[f64]) -> Vec<f64> {
    masses
        .iter()
        .scan(0.0, |total, m| {
            *total += m;
            Some(*total)
        })
        .collect()
}

/// The cell a uniform `u` in [0, 1) falls in, by the running sums of the
/// cells' masses.
pub(crate) fn pick(cumulative: &[f64], u: f64) -> usize {
    let total = cumulative.last().copied().unwrap_or(0.0);
    cumulative
        .partition_point(|&c| c <= u * total)
        .min(cumulative.len().saturating_sub(1))
}

/// Where in [0, 1] a density rising linearly from `p0` to `p1` puts the
/// share `u` of its mass: the root in [0, 1] of
/// `(p1 − p0) s² / 2 + p0 s = u (p0 + p1) / 2`, in the form that loses no
/// digits as `p1 − p0` vanishes.
pub(crate) fn linear_draw(p0: f64, p1: f64, u: f64) -> f64 {
    let c = u * (p0 + p1) / 2.0;
    let root = (p0 * p0 + 2.0 * (p1 - p0) * c).max(0.0).sqrt();
    if p0 + root > 0.0 {
        (2.0 * c / (p0 + root)).clamp(0.0, 1.0)
    } else {
        u
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_linear_density_is_inverted_in_closed_form() {
        // Density 2s on [0, 1]: its distribution function s², so u falls
        // at sqrt(u); a flat density at u; density 2(1 - s) at
        // 1 - sqrt(1 - u).
        for u in [0.0, 0.1, 0.37, 0.5, 0.93, 1.0] {
            assert!((linear_draw(0.0, 1.0, u) - u.sqrt()).abs() < 1e-15);
            assert!((linear_draw(0.3, 0.3, u) - u).abs() < 1e-15);
            assert!((linear_draw(1.0, 0.0, u) - (1.0 - (1.0 - u).sqrt())).abs() < 1e-12);
            // Ends 1e-12 apart are the flat density's, to the digit.
            assert!((linear_draw(1.0, 1.0 + 1e-12, u) - u).abs() < 1e-12);
        }
    }

    #[test]
    fn a_cell_is_picked_by_its_share_of_the_mass() {
        let cumulative = running_sums(&[1.0, 0.0, 3.0]);
        assert_eq!(cumulative, vec![1.0, 1.0, 4.0]);
        assert_eq!(pick(&cumulative, 0.0), 0);
        assert_eq!(pick(&cumulative, 0.2499), 0);
        // The empty cell is never picked.
        assert_eq!(pick(&cumulative, 0.25), 2);
        assert_eq!(pick(&cumulative, 0.9999), 2);
    }
}
