//! The bootstrap particle filter of the paper's comparisons: particles
//! carry a state and a parameter vector drawn from the prior; theta follows
//! a random walk ("jitter") so that resampling does not collapse it.

use crate::InvalidSetting;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use twostage_models::{
    IoData, MEASUREMENT_NOISE_VARIANCE, PROCESS_NOISE_VARIANCE, Prior, StreamPurpose, stream_rng,
};

use crate::error::{BaselineError, Result};
use crate::{Estimate, RecordEstimator};

/// A model a particle filter can run: a state that moves from sample to
/// sample given theta and the input, observed through one noisy output.
pub trait ParticleModel: Send + Sync {
    /// Per-block scratch space of [`ParticleModel::propagate`] (an
    /// integrator's buffers, for instance).
    type Scratch: Send;
    /// A fresh scratch space.
    fn scratch(&self) -> Self::Scratch;
    /// The state dimension.
    fn state_dim(&self) -> usize;
    /// The prior box of theta.
    fn prior(&self) -> &Prior;
    /// Variance of the measurement noise.
    fn measurement_variance(&self) -> f64;
    /// The state at sample 0.
    fn initial_state(&self, theta: &[f64], state: &mut [f64]);
    /// The noise-free output at sample `k`.
    fn output(&self, k: usize, theta: &[f64], state: &[f64], inputs: &[f64]) -> f64;
    /// Move the state from sample `k` to `k + 1`, drawing process noise from `rng`.
    fn propagate(
        &self,
        k: usize,
        theta: &[f64],
        state: &mut [f64],
        inputs: &[f64],
        rng: &mut ChaCha8Rng,
        scratch: &mut Self::Scratch,
    );
}

/// The benchmark of eq. (5) for the particle filter.
#[derive(Debug, Clone)]
pub struct BenchmarkParticles {
    prior: Prior,
}

impl BenchmarkParticles {
    /// The paper's benchmark, theta in [-0.9, 0.9].
    ///
    /// # Errors
    /// Never for the built-in box.
    pub fn new() -> Result<Self> {
        Ok(Self {
            prior: Prior::uniform_box(&[-0.9], &[0.9])?,
        })
    }
}

impl ParticleModel for BenchmarkParticles {
    type Scratch = ();
    fn scratch(&self) {}
    fn state_dim(&self) -> usize {
        2
    }
    fn prior(&self) -> &Prior {
        &self.prior
    }
    fn measurement_variance(&self) -> f64 {
        MEASUREMENT_NOISE_VARIANCE
    }
    fn initial_state(&self, _theta: &[f64], state: &mut [f64]) {
        state.fill(0.0);
    }
    fn output(&self, _k: usize, _theta: &[f64], state: &[f64], _inputs: &[f64]) -> f64 {
        state[1]
    }
    fn propagate(
        &self,
        k: usize,
        theta: &[f64],
        state: &mut [f64],
        inputs: &[f64],
        rng: &mut ChaCha8Rng,
        _scratch: &mut (),
    ) {
        let (a, b) = twostage_models::Benchmark::coefficients(theta[0]);
        let sd = PROCESS_NOISE_VARIANCE.sqrt();
        let v11: f64 = StandardNormal.sample(rng);
        let v12: f64 = StandardNormal.sample(rng);
        let (x1, x2) = (state[0], state[1]);
        state[0] = 0.5 * x1 + inputs[k] + sd * v11;
        state[1] = a * x1 - theta[0] * x2 + b * inputs[k] + sd * v12;
    }
}

/// Settings of the bootstrap particle filter.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `particles` | 1000 | >= 2 |
/// | `jitter` | 1e-3 | >= 0: the random walk of each theta component per sample, as a share of its prior width (the benchmark: sd 1.8e-3, variance about 3e-6) |
/// | `seed` | 0 | any |
#[derive(Debug, Clone, PartialEq)]
pub struct ParticleFilter<M> {
    model: M,
    particles: usize,
    jitter: f64,
    seed: u64,
    name: String,
}

/// Particles per parallel block: each block owns one random stream, so the
/// result does not depend on the thread count.
const BLOCK: usize = 64;

impl<M: ParticleModel> ParticleFilter<M> {
    /// A filter with `particles` particles and the defaults above (fewer
    /// than 2 particles is refused at estimate time).
    pub fn new(model: M, particles: usize) -> Self {
        Self {
            model,
            particles,
            jitter: 1e-3,
            seed: 0,
            name: format!("pf{particles}"),
        }
    }

    /// The random-walk step of theta, as a share of the prior width.
    pub fn jitter(mut self, jitter: f64) -> Self {
        self.jitter = jitter;
        self
    }

    /// The seed of the filter's random streams.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    fn run(&self, record: &IoData) -> Result<Estimate> {
        if record.n_inputs() != 1 || record.n_outputs() != 1 {
            return Err(BaselineError::Shape {
                what: "the record's inputs and outputs",
                found: format!("{} and {}", record.n_inputs(), record.n_outputs()),
                expected: "one of each (the particle filter is SISO)".into(),
            });
        }
        record.check_finite()?;
        if self.particles < 2 || self.jitter.is_nan() || self.jitter < 0.0 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "particles and jitter",
                value: format!("{} and {}", self.particles, self.jitter),
                reason: "at least 2 particles and a jitter >= 0".into(),
            }));
        }
        let (u, y) = (record.input(0), record.output(0));
        let prior = self.model.prior();
        let (q, dx, n_p) = (prior.dim(), self.model.state_dim(), self.particles);
        let steps: Vec<f64> = prior
            .lower()
            .iter()
            .zip(prior.upper())
            .map(|(lo, hi)| self.jitter * (hi - lo))
            .collect();
        let design = prior.design(n_p, self.seed)?;
        let mut thetas = vec![0.0; n_p * q];
        for (i, t) in thetas.chunks_exact_mut(q).enumerate() {
            design.fill_theta(i, t)?;
        }
        let mut states = vec![0.0; n_p * dx];
        for (s, t) in states.chunks_exact_mut(dx).zip(thetas.chunks_exact(q)) {
            self.model.initial_state(t, s);
        }
        let mut rngs: Vec<(ChaCha8Rng, M::Scratch)> = (0..n_p.div_ceil(BLOCK))
            .map(|b| {
                (
                    stream_rng(self.seed, b as u64, StreamPurpose::Simulation),
                    self.model.scratch(),
                )
            })
            .collect();
        let mut resampler = stream_rng(self.seed, u64::MAX, StreamPurpose::Design);
        let mut log_w = vec![0.0; n_p];
        let mut weights = vec![0.0; n_p];
        let var = self.model.measurement_variance();
        let (mut new_states, mut new_thetas) = (vec![0.0; n_p * dx], vec![0.0; n_p * q]);
        for k in 0..y.len() {
            // Weight by the likelihood of y(k).
            for (i, lw) in log_w.iter_mut().enumerate() {
                let pred = self.model.output(
                    k,
                    &thetas[i * q..(i + 1) * q],
                    &states[i * dx..(i + 1) * dx],
                    u,
                );
                let e = y[k] - pred;
                *lw += -0.5 * e * e / var;
            }
            let max = log_w.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
            if !max.is_finite() {
                return Err(BaselineError::Numerical {
                    sample: k,
                    what: "every particle's weight vanished".into(),
                });
            }
            let mut total = 0.0;
            for (w, lw) in weights.iter_mut().zip(&log_w) {
                *w = (lw - max).exp();
                total += *w;
            }
            for w in weights.iter_mut() {
                *w /= total;
            }
            if k + 1 == y.len() {
                break;
            }
            let ess = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
            if ess < 0.5 * n_p as f64 {
                // Systematic resampling: one uniform, n_p evenly spaced pointers.
                let offset: f64 = resampler.random::<f64>() / n_p as f64;
                let (mut cumulative, mut j) = (weights[0], 0);
                for i in 0..n_p {
                    let pointer = offset + i as f64 / n_p as f64;
                    while pointer > cumulative && j + 1 < n_p {
                        j += 1;
                        cumulative += weights[j];
                    }
                    new_states[i * dx..(i + 1) * dx].copy_from_slice(&states[j * dx..(j + 1) * dx]);
                    new_thetas[i * q..(i + 1) * q].copy_from_slice(&thetas[j * q..(j + 1) * q]);
                }
                std::mem::swap(&mut states, &mut new_states);
                std::mem::swap(&mut thetas, &mut new_thetas);
                log_w.fill(0.0);
            }
            // Propagate every particle, block by block in parallel.
            states
                .par_chunks_mut(BLOCK * dx)
                .zip(thetas.par_chunks_mut(BLOCK * q))
                .zip(rngs.par_iter_mut())
                .for_each(|((s_block, t_block), (rng, scratch))| {
                    for (s, t) in s_block
                        .chunks_exact_mut(dx)
                        .zip(t_block.chunks_exact_mut(q))
                    {
                        self.model.propagate(k, t, s, u, rng, scratch);
                        for (tj, step) in t.iter_mut().zip(&steps) {
                            let z: f64 = StandardNormal.sample(rng);
                            *tj += step * z;
                        }
                    }
                });
        }
        let mut mean = vec![0.0; q];
        for (w, t) in weights.iter().zip(thetas.chunks_exact(q)) {
            for (m, tj) in mean.iter_mut().zip(t) {
                *m += w * tj;
            }
        }
        let mut spread = vec![0.0; q];
        for (w, t) in weights.iter().zip(thetas.chunks_exact(q)) {
            for ((s, tj), m) in spread.iter_mut().zip(t).zip(&mean) {
                *s += w * (tj - m) * (tj - m);
            }
        }
        let mut theta = mean;
        prior.clip(&mut theta);
        Ok(Estimate {
            theta,
            spread: Some(spread.into_iter().map(f64::sqrt).collect()),
        })
    }
}

impl<M: ParticleModel> RecordEstimator for ParticleFilter<M> {
    fn name(&self) -> &str {
        &self.name
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        self.run(record)
    }
}
