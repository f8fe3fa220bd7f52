//! The refined estimate's own uncertainty against Monte Carlo: intervals
//! of least-squares estimates under autocorrelated noise cover as often as
//! they say, where the classic white-noise formula would not.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rand::RngExt;
use twostage_models::{IoData, Prior, experiment_rng};
use twostage_refine::{RefineError, Refinement, ResidualModel};

/// y_t = a + b u_t + e_t: residuals y - a - b u.
struct Line(Prior);

impl ResidualModel for Line {
    type Error = RefineError;
    fn prior(&self) -> &Prior {
        &self.0
    }
    fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
        for ((r, u), y) in r.iter_mut().zip(record.input(0)).zip(record.output(0)) {
            *r = y - theta[0] - theta[1] * u;
        }
        Ok(())
    }
}

/// An AR(1) series of coefficient `rho` and unit innovations.
fn ar1(rho: f64, n: usize, rng: &mut impl RngExt) -> Vec<f64> {
    let mut x = 0.0;
    (0..n + 100)
        .map(|_| {
            let e: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng);
            x = rho * x + e;
            x
        })
        .skip(100)
        .collect()
}

/// The least-squares line through (u, y), by the normal equations.
fn least_squares(u: &[f64], y: &[f64]) -> [f64; 2] {
    let n = u.len() as f64;
    let (mu, my) = (u.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = u.iter().zip(y).map(|(u, y)| (u - mu) * (y - my)).sum();
    let sxx: f64 = u.iter().map(|u| (u - mu) * (u - mu)).sum();
    let b = sxy / sxx;
    [my - b * mu, b]
}

#[test]
fn intervals_under_autocorrelated_noise_cover_as_often_as_they_say() {
    let fit = Refinement::new(Line(
        Prior::uniform_box(&[-10.0, -10.0], &[10.0, 10.0]).unwrap(),
    ));
    let truth = [1.0, 2.0];
    let (replications, n) = (1000, 400);
    let mut covered = [0usize; 2];
    let mut naive_covered = 0usize;
    for k in 0..replications {
        let mut rng = experiment_rng(5, k as u64);
        let u = ar1(0.7, n, &mut rng);
        let e = ar1(0.8, n, &mut rng);
        let y: Vec<f64> = u
            .iter()
            .zip(&e)
            .map(|(u, e)| truth[0] + truth[1] * u + 0.5 * e)
            .collect();
        let record = IoData::siso(&u, &y).unwrap();
        let theta = least_squares(&u, &y);
        let local = fit.uncertainty(&record, &theta).unwrap();
        let w = local.half_widths(0.1);
        for j in 0..2 {
            covered[j] += usize::from((theta[j] - truth[j]).abs() <= w[j]);
        }
        // The white-noise formula for b: s^2 / sum (u - mean u)^2.
        let mean = u.iter().sum::<f64>() / n as f64;
        let sxx: f64 = u.iter().map(|v| (v - mean) * (v - mean)).sum();
        let s2: f64 = u
            .iter()
            .zip(&y)
            .map(|(u, y)| (y - theta[0] - theta[1] * u).powi(2))
            .sum::<f64>()
            / (n - 2) as f64;
        naive_covered += usize::from((theta[1] - truth[1]).abs() <= 1.645 * (s2 / sxx).sqrt());
        assert!((local.correlation[1] - local.correlation[2]).abs() < 1e-12);
    }
    let share = |c: usize| c as f64 / replications as f64;
    // 1000 replications: a share moves by about 0.01 from chance alone.
    for (j, c) in covered.iter().enumerate() {
        assert!(
            (0.85..=0.95).contains(&share(*c)),
            "parameter {j}: {}",
            share(*c)
        );
    }
    assert!(
        share(naive_covered) < 0.8,
        "the naive formula: {}",
        share(naive_covered)
    );
}

/// y_t = a u_t + h 0.5^t + e_t: h, like an initial state, shows in the
/// first few samples only.
struct Transient(Prior);

impl ResidualModel for Transient {
    type Error = RefineError;
    fn prior(&self) -> &Prior {
        &self.0
    }
    fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
        let mut decay = 1.0;
        for ((r, u), y) in r.iter_mut().zip(record.input(0)).zip(record.output(0)) {
            *r = y - theta[0] * u - theta[1] * decay;
            decay *= 0.5;
        }
        Ok(())
    }
}

#[test]
fn a_parameter_that_only_the_first_samples_determine_is_covered_as_often_as_said() {
    let fit = Refinement::new(Transient(
        Prior::uniform_box(&[-10.0, -10.0], &[10.0, 10.0]).unwrap(),
    ));
    let truth = [2.0, 3.0];
    let (replications, n) = (1000, 300);
    let mut covered = [0usize; 2];
    for k in 0..replications {
        let mut rng = experiment_rng(6, k as u64);
        let u = ar1(0.5, n, &mut rng);
        let y: Vec<f64> = u
            .iter()
            .enumerate()
            .map(|(t, u)| {
                let e: f64 =
                    rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                truth[0] * u + truth[1] * 0.5f64.powi(t as i32) + 0.2 * e
            })
            .collect();
        // Least squares by the normal equations of the two regressors.
        let decay: Vec<f64> = (0..n).map(|t| 0.5f64.powi(t as i32)).collect();
        let dot = |x: &[f64], z: &[f64]| x.iter().zip(z).map(|(a, b)| a * b).sum::<f64>();
        let (suu, sud, sdd) = (dot(&u, &u), dot(&u, &decay), dot(&decay, &decay));
        let (suy, sdy) = (dot(&u, &y), dot(&decay, &y));
        let det = suu * sdd - sud * sud;
        let theta = [(sdd * suy - sud * sdy) / det, (suu * sdy - sud * suy) / det];
        let record = IoData::siso(&u, &y).unwrap();
        let local = fit.uncertainty(&record, &theta).unwrap();
        let w = local.half_widths(0.1);
        for j in 0..2 {
            covered[j] += usize::from((theta[j] - truth[j]).abs() <= w[j]);
        }
    }
    for (j, c) in covered.iter().enumerate() {
        let share = *c as f64 / replications as f64;
        assert!((0.85..=0.95).contains(&share), "parameter {j}: {share}");
    }
}

#[test]
fn the_reported_correlation_is_the_estimates_own() {
    let fit = Refinement::new(Line(
        Prior::uniform_box(&[-10.0, -10.0], &[10.0, 10.0]).unwrap(),
    ));
    let (replications, n) = (1000, 300);
    let (mut estimates, mut reported) = (Vec::new(), 0.0);
    for k in 0..replications {
        let mut rng = experiment_rng(7, k as u64);
        // An input away from zero: intercept and slope trade off.
        let u: Vec<f64> = ar1(0.7, n, &mut rng).iter().map(|v| 2.0 + v).collect();
        let e = ar1(0.5, n, &mut rng);
        let y: Vec<f64> = u
            .iter()
            .zip(&e)
            .map(|(u, e)| 1.0 + 2.0 * u + 0.5 * e)
            .collect();
        let theta = least_squares(&u, &y);
        let local = fit
            .uncertainty(&IoData::siso(&u, &y).unwrap(), &theta)
            .unwrap();
        reported += local.correlation[1] / replications as f64;
        estimates.push(theta);
    }
    let mean = |j: usize| estimates.iter().map(|t| t[j]).sum::<f64>() / replications as f64;
    let (ma, mb) = (mean(0), mean(1));
    let moment = |f: &dyn Fn(&[f64; 2]) -> f64| estimates.iter().map(f).sum::<f64>();
    let empirical = moment(&|t| (t[0] - ma) * (t[1] - mb))
        / (moment(&|t| (t[0] - ma).powi(2)) * moment(&|t| (t[1] - mb).powi(2))).sqrt();
    assert!(empirical < -0.5, "{empirical}");
    assert!(
        (reported - empirical).abs() < 0.05,
        "reported {reported}, Monte Carlo {empirical}"
    );
}
