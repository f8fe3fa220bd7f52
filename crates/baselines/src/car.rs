//! The competitors on the Pacejka car (Section 6): its particle model, its
//! simulation-error predictor, and its Bayes-optimal reference. The car is
//! deterministic but for the accelerometer noise, so the predictor of y(k)
//! is the noise-free simulation.
//!
//! These run the car with its own input signal (the chicane by default);
//! the record's sampled input is used only between samples by models whose
//! input is not the chicane.

use crate::InvalidSetting;
use rand::{Rng, RngExt};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use twostage_models::{IoData, PACEJKA_NOISE_VARIANCE, PacejkaCar, Prior, Rk4, Simulator};
use twostage_refine::{ResidualModel, WeightedMoments};

use crate::bayes::{linear_draw, pick, running_sums};
use crate::error::{BaselineError, Result};
use crate::particle::ParticleModel;
use crate::{Estimate, RecordEstimator};

fn state4(state: &mut [f64]) -> Result<&mut [f64; 4]> {
    let length = state.len();
    <&mut [f64; 4]>::try_from(state).map_err(|_| BaselineError::Shape {
        what: "the car's state",
        found: format!("{length} components"),
        expected: "four (beta, r, phi, p)".into(),
    })
}

/// The car for the particle filter: state (beta, r, phi, p), no process
/// noise, theta = (pK1, pK2).
#[derive(Debug, Clone)]
pub struct CarParticles {
    car: PacejkaCar,
}

impl CarParticles {
    /// The paper's car with its chicane.
    pub fn new() -> Self {
        Self {
            car: PacejkaCar::new(),
        }
    }
}

impl Default for CarParticles {
    fn default() -> Self {
        Self::new()
    }
}

impl ParticleModel for CarParticles {
    type Scratch = Rk4;
    fn scratch(&self) -> Rk4 {
        Rk4::new(4)
    }
    fn state_dim(&self) -> usize {
        4
    }
    fn prior(&self) -> &Prior {
        self.car.prior()
    }
    fn measurement_variance(&self) -> f64 {
        PACEJKA_NOISE_VARIANCE
    }
    fn initial_state(&self, _theta: &[f64], state: &mut [f64]) {
        state.fill(0.0);
    }
    fn output(&self, k: usize, theta: &[f64], state: &[f64], inputs: &[f64]) -> f64 {
        let mut x = [0.0; 4];
        x.copy_from_slice(&state[..4]);
        self.car.output_at(theta, k, &x, inputs)
    }
    fn propagate(
        &self,
        k: usize,
        theta: &[f64],
        state: &mut [f64],
        inputs: &[f64],
        _rng: &mut ChaCha8Rng,
        rk4: &mut Rk4,
    ) {
        if let Ok(x) = state4(state) {
            self.car.advance(theta, k, x, inputs, rk4);
        }
    }
}

/// The car's noise-free prediction, for the prediction-error method.
#[derive(Debug, Clone)]
pub struct CarPredictor {
    car: PacejkaCar,
}

impl CarPredictor {
    /// The paper's car with its chicane.
    pub fn new() -> Self {
        Self {
            car: PacejkaCar::new(),
        }
    }
}

impl Default for CarPredictor {
    fn default() -> Self {
        Self::new()
    }
}

/// The noise-free output of the car at theta over `n` samples.
fn noise_free(car: &PacejkaCar, theta: &[f64], inputs: &[f64], out: &mut [f64]) -> Result<()> {
    let mut rk4 = Rk4::new(4);
    let mut x = [0.0f64; 4];
    for (k, y_k) in out.iter_mut().enumerate() {
        if k > 0 {
            car.advance(theta, k - 1, &mut x, inputs, &mut rk4);
        }
        *y_k = car.output_at(theta, k, &x, inputs);
        if !y_k.is_finite() {
            return Err(BaselineError::Numerical {
                sample: k,
                what: format!("the car diverged at theta = {theta:?}"),
            });
        }
    }
    Ok(())
}

impl ResidualModel for CarPredictor {
    type Error = BaselineError;
    fn prior(&self) -> &Prior {
        self.car.prior()
    }
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<()> {
        if record.n_inputs() != 1 || record.n_outputs() != 1 {
            return Err(BaselineError::Shape {
                what: "the record's inputs and outputs",
                found: format!("{} and {}", record.n_inputs(), record.n_outputs()),
                expected: "one of each (the car is SISO)".into(),
            });
        }
        noise_free(&self.car, theta, record.input(0), residuals)?;
        for (r, y) in residuals.iter_mut().zip(record.output(0)) {
            *r = y - *r;
        }
        Ok(())
    }
}

/// The car's posterior of (pK1, pK2) given one record, on a grid.
#[derive(Debug, Clone, PartialEq)]
pub struct CarPosterior {
    /// Posterior mean.
    pub mean: [f64; 2],
    /// Posterior standard deviations.
    pub sd: [f64; 2],
    /// The grid point of highest density.
    pub map: [f64; 2],
    /// How far the mean moved between the half-resolution subgrid and the
    /// full grid, per parameter: the grid's integration error is far below.
    pub grid_change: [f64; 2],
}

/// The Bayes-optimal reference for the car: noise-free trajectories are
/// simulated once on a regular grid over the prior box (in parallel) and
/// shared by every record; a record's posterior is proportional to
/// `exp(-||y - y(theta)||^2 / (2 * 0.01))` on the grid, integrated by the
/// trapezoid rule.
///
/// | setting | default | meaning |
/// |---|---|---|
/// | grid | 129 x 65 | points in pK1 x pK2; steps 0.121 and 0.00375, about a quarter and a tenth of the posterior's spreads |
#[derive(Debug, Clone)]
pub struct BayesCar {
    n1: usize,
    n2: usize,
    lower: [f64; 2],
    step: [f64; 2],
    n_samples: usize,
    trajectories: Vec<f64>,
    /// The noise-free car the grid was simulated with.
    car: PacejkaCar,
    /// Its steering samples, when they are a given input every record
    /// shares (a manoeuvre); `None` for the car's own chicane.
    steering: Option<Vec<f64>>,
}

impl BayesCar {
    /// Points a side of the grid the reference draws are taken from by
    /// default: steps of 0.1875 sd over +- 6 sd.
    pub const DRAW_POINTS: usize = 65;

    /// Simulate the grid (n1 x n2 noise-free car runs of `n_samples` samples).
    ///
    /// # Errors
    /// A grid smaller than 3 x 3, or a simulation that fails.
    pub fn new(n1: usize, n2: usize, n_samples: usize) -> Result<Self> {
        let car = PacejkaCar::builder().n_samples(n_samples).build()?;
        Self::simulate(n1, n2, car, None)
    }

    /// The reference for records of the car driven by one given steering
    /// (a manoeuvre every record shares, sampled as the records are): the
    /// grid is simulated on it, and a record of another steering is
    /// refused.
    ///
    /// # Errors
    /// As [`BayesCar::new`], and a steering the car refuses.
    pub fn on_steering(n1: usize, n2: usize, steering: Vec<f64>) -> Result<Self> {
        let car = PacejkaCar::builder()
            .n_samples(steering.len())
            .input(twostage_models::InputSignal::fixed(steering.clone())?)
            .build()?;
        Self::simulate(n1, n2, car, Some(steering))
    }

    fn simulate(n1: usize, n2: usize, car: PacejkaCar, steering: Option<Vec<f64>>) -> Result<Self> {
        if n1 < 3 || n2 < 3 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "grid",
                value: format!("{n1} x {n2}"),
                reason: "at least 3 x 3 points".into(),
            }));
        }
        let n_samples = car.spec().n_samples();
        let (lo, hi) = (car.prior().lower(), car.prior().upper());
        let lower = [lo[0], lo[1]];
        let step = [
            (hi[0] - lo[0]) / (n1 - 1) as f64,
            (hi[1] - lo[1]) / (n2 - 1) as f64,
        ];
        // The chicane is the car's own; a given steering is read from its
        // samples.
        let inputs = steering.clone().unwrap_or_else(|| vec![0.0; n_samples]);
        let trajectories: Vec<Vec<f64>> = (0..n1 * n2)
            .into_par_iter()
            .map(|g| {
                let theta = [
                    lower[0] + step[0] * (g / n2) as f64,
                    lower[1] + step[1] * (g % n2) as f64,
                ];
                let mut y = vec![0.0; n_samples];
                noise_free(&car, &theta, &inputs, &mut y).map(|()| y)
            })
            .collect::<Result<_>>()?;
        Ok(Self {
            n1,
            n2,
            lower,
            step,
            n_samples,
            trajectories: trajectories.concat(),
            car,
            steering,
        })
    }

    /// The paper-scale grid: 129 x 65 points, 500 samples.
    ///
    /// # Errors
    /// As [`BayesCar::new`].
    pub fn paper() -> Result<Self> {
        Self::new(129, 65, 500)
    }

    fn theta(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.lower[0] + self.step[0] * i as f64,
            self.lower[1] + self.step[1] * j as f64,
        ]
    }

    /// A record driven by another steering than the grid's is refused.
    fn check_steering(&self, record: &IoData) -> Result<()> {
        let Some(steering) = &self.steering else {
            return Ok(());
        };
        let same = record.n_inputs() == 1
            && record
                .input(0)
                .iter()
                .zip(steering)
                .all(|(a, b)| (a - b).abs() <= 1e-9 * b.abs().max(1e-6));
        if same {
            Ok(())
        } else {
            Err(BaselineError::Shape {
                what: "the record's steering",
                found: "another steering".into(),
                expected: "the steering the grid was simulated on".into(),
            })
        }
    }

    /// The posterior given one record.
    ///
    /// # Errors
    /// A record of another length, or not SISO, or (for a grid on a given
    /// steering) of another steering.
    pub fn posterior(&self, record: &IoData) -> Result<CarPosterior> {
        if record.n_outputs() != 1 || record.n_samples() != self.n_samples {
            return Err(BaselineError::Shape {
                what: "the record",
                found: format!(
                    "{} samples of {} outputs",
                    record.n_samples(),
                    record.n_outputs()
                ),
                expected: format!(
                    "{} samples of one output (what the grid was simulated for)",
                    self.n_samples
                ),
            });
        }
        record.check_finite()?;
        self.check_steering(record)?;
        let y = record.output(0);
        let log_post: Vec<f64> = self
            .trajectories
            .par_chunks(self.n_samples)
            .map(|t| {
                -t.iter().zip(y).map(|(a, b)| (a - b) * (a - b)).sum::<f64>()
                    / (2.0 * PACEJKA_NOISE_VARIANCE)
            })
            .collect();
        let full = self.moments(&log_post, 1);
        let half = self.moments(&log_post, 2);
        Ok(CarPosterior {
            grid_change: [(full.0[0] - half.0[0]).abs(), (full.0[1] - half.0[1]).abs()],
            mean: full.0,
            sd: full.1,
            map: full.2,
        })
    }

    /// Refine a grid posterior locally: simulate afresh a grid of
    /// `(2^(l+4) + 1)^2` points over the mean +- 5 sd (clipped to the box) at
    /// levels l = 0, 1, ..., until the mean moves by less than
    /// `tolerance` sd in both parameters between two levels.
    ///
    /// # Errors
    /// As [`BayesCar::posterior`], or a simulation that fails.
    pub fn refine(
        &self,
        record: &IoData,
        grid: &CarPosterior,
        tolerance: f64,
        max_levels: usize,
    ) -> Result<(CarPosterior, usize)> {
        self.check_steering(record)?;
        let y = record.output(0);
        let mut previous: Option<CarPosterior> = None;
        for level in 0..max_levels.max(1) {
            let points = (1usize << (level + 4)) + 1;
            let (lo, step, log_post) = self.local_grid(y, grid, 5.0, points)?;
            let local = Self {
                n1: points,
                n2: points,
                lower: lo,
                step,
                n_samples: self.n_samples,
                trajectories: Vec::new(),
                car: self.car.clone(),
                steering: None,
            };
            let (mean, sd, map) = local.moments(&log_post, 1);
            let current = CarPosterior {
                mean,
                sd,
                map,
                grid_change: previous.as_ref().map_or([f64::INFINITY; 2], |p| {
                    [(mean[0] - p.mean[0]).abs(), (mean[1] - p.mean[1]).abs()]
                }),
            };
            let converged =
                (0..2).all(|d| current.grid_change[d] < tolerance * current.sd[d].max(1e-12));
            previous = Some(current);
            if converged {
                return Ok((previous.unwrap_or_else(|| grid.clone()), level + 1));
            }
        }
        Ok((previous.unwrap_or_else(|| grid.clone()), max_levels.max(1)))
    }

    /// The log posterior (up to a constant) of the output `y` on a grid of
    /// `points` x `points` simulated afresh over `grid`'s mean +- `spreads`
    /// sd (clipped to the prior's box): the grid's lower corner, steps and
    /// values (pK1 major).
    fn local_grid(
        &self,
        y: &[f64],
        grid: &CarPosterior,
        spreads: f64,
        points: usize,
    ) -> Result<([f64; 2], [f64; 2], Vec<f64>)> {
        let car = &self.car;
        let (box_lo, box_hi) = (car.prior().lower(), car.prior().upper());
        let mut lo = [0.0; 2];
        let mut step = [0.0; 2];
        for d in 0..2 {
            let spread = spreads * grid.sd[d].max(1e-9);
            lo[d] = (grid.mean[d] - spread).max(box_lo[d]);
            let hi = (grid.mean[d] + spread).min(box_hi[d]);
            step[d] = (hi - lo[d]) / (points - 1) as f64;
        }
        let inputs = self
            .steering
            .clone()
            .unwrap_or_else(|| vec![0.0; self.n_samples]);
        let log_post = (0..points * points)
            .into_par_iter()
            .map(|g| {
                let theta = [
                    lo[0] + step[0] * (g / points) as f64,
                    lo[1] + step[1] * (g % points) as f64,
                ];
                let mut prediction = vec![0.0; self.n_samples];
                noise_free(car, &theta, &inputs, &mut prediction)?;
                let sse: f64 = prediction
                    .iter()
                    .zip(y)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
                Ok(-sse / (2.0 * PACEJKA_NOISE_VARIANCE))
            })
            .collect::<Result<_>>()?;
        Ok((lo, step, log_post))
    }

    /// `count` independent draws of (pK1, pK2) from the posterior given
    /// `record`: the density simulated afresh on a grid of `points`²
    /// over the grid posterior's mean +- 6 sd (clipped to the prior's box),
    /// interpolated bilinearly between its points and drawn from exactly
    /// (a cell by its mass, then pK1 by the cell's marginal and pK2 given
    /// it, each linear); the reference a posterior's draws are tested
    /// against. Linear interpolation on steps of h sd widens a normal's
    /// variance by about h²/6: [`BayesCar::DRAW_POINTS`] keeps it to 0.6%.
    ///
    /// # Errors
    /// As [`BayesCar::posterior`], fewer than 3 points, or a simulation
    /// that fails.
    pub fn draws(
        &self,
        record: &IoData,
        count: usize,
        points: usize,
        rng: &mut impl Rng,
    ) -> Result<Vec<[f64; 2]>> {
        if points < 3 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "points",
                value: points.to_string(),
                reason: "at least 3 points a side".into(),
            }));
        }
        let coarse = self.posterior(record)?;
        let n = points;
        let (lo, step, log_post) = self.local_grid(record.output(0), &coarse, 6.0, n)?;
        let peak = log_post.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
        let density: Vec<f64> = log_post.iter().map(|v| (v - peak).exp()).collect();
        let at = |i: usize, j: usize| density[i * n + j];
        let cells: Vec<f64> = (0..(n - 1) * (n - 1))
            .map(|c| {
                let (i, j) = (c / (n - 1), c % (n - 1));
                at(i, j) + at(i + 1, j) + at(i, j + 1) + at(i + 1, j + 1)
            })
            .collect();
        let cumulative = running_sums(&cells);
        Ok((0..count)
            .map(|_| {
                let c = pick(&cumulative, rng.random());
                let (i, j) = (c / (n - 1), c % (n - 1));
                let (p00, p10, p01, p11) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                let s = linear_draw(p00 + p01, p10 + p11, rng.random());
                let t = linear_draw(p00 + s * (p10 - p00), p01 + s * (p11 - p01), rng.random());
                [
                    lo[0] + step[0] * (i as f64 + s),
                    lo[1] + step[1] * (j as f64 + t),
                ]
            })
            .collect())
    }

    /// Mean, sd and mode by the trapezoid rule on every `stride`-th point.
    fn moments(&self, log_post: &[f64], stride: usize) -> ([f64; 2], [f64; 2], [f64; 2]) {
        let peak = log_post.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
        let mut moments = WeightedMoments::new(2);
        let mut map = (f64::NEG_INFINITY, [0.0; 2]);
        let last = |n: usize| (n - 1) / stride * stride;
        for i in (0..self.n1).step_by(stride) {
            for j in (0..self.n2).step_by(stride) {
                let lp = log_post[i * self.n2 + j];
                let theta = self.theta(i, j);
                if lp > map.0 {
                    map = (lp, theta);
                }
                let wi = if i == 0 || i == last(self.n1) {
                    0.5
                } else {
                    1.0
                };
                let wj = if j == 0 || j == last(self.n2) {
                    0.5
                } else {
                    1.0
                };
                moments.add(wi * wj * (lp - peak).exp(), &theta);
            }
        }
        let (mean, sd) = moments.mean_and_sd();
        ([mean[0], mean[1]], [sd[0], sd[1]], map.1)
    }
}

impl RecordEstimator for BayesCar {
    fn name(&self) -> &str {
        "bayes"
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        let p = self.posterior(record)?;
        Ok(Estimate {
            theta: p.mean.to_vec(),
            spread: Some(p.sd.to_vec()),
        })
    }
}
