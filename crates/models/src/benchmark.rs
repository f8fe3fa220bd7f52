//! The benchmark system of Section 5 of the paper, eq. (5).

use rand_distr::{Distribution, StandardNormal};

use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::input::InputSignal;
use crate::prior::Prior;
use crate::rng::ExperimentRng;
use crate::simulator::{Capabilities, Conditions, ModelSpec, Simulator, check_theta};

/// Default record length of the paper's benchmark.
pub const BENCHMARK_SAMPLES: usize = 1000;
/// Variance of the process noises v11 and v12.
pub const PROCESS_NOISE_VARIANCE: f64 = 1.0;
/// Variance of the measurement noise v2.
pub const MEASUREMENT_NOISE_VARIANCE: f64 = 0.1;

/// The paper's benchmark, eq. (5):
///
/// ```text
/// x1(k+1) = x1(k) / 2 + u(k) + v11(k)
/// x2(k+1) = (1 - theta^2) sin(50 theta^2) x1(k) - theta x2(k) + theta / (1 + theta^2) u(k) + v12(k)
/// y(k)    = x2(k) + v2(k)
/// ```
///
/// with `x(0) = 0`, `v11, v12 ~ WGN(0, 1)`, `v2 ~ WGN(0, 0.1)`, `u ~ WGN(0, 1)`
/// drawn per experiment, `theta` in `[-0.9, 0.9]`, and samples
/// `(u(k), y(k))` for `k = 0..N-1`, `N = 1000` by default.
///
/// Per sample k the stream is read in a fixed order: the whole input first,
/// then `v2(k)`, `v11(k)`, `v12(k)` for k = 0, 1, ...
///
/// ```
/// use twostage_models::{experiment_rng, Benchmark, NoiseFree, Simulator};
/// let model = NoiseFree::new(Box::new(Benchmark::builder().n_samples(200).build()?))?;
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.5], &mut experiment_rng(0, 0), &mut record)?;
/// // Noise-free, x2(0) = 0 and x2(1) = theta / (1 + theta^2) u(0).
/// let (u, y) = (record.input(0), record.output(0));
/// assert_eq!(y[0], 0.0);
/// assert!((y[1] - 0.4 * u[0]).abs() < 1e-15);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Benchmark {
    spec: ModelSpec,
    input: InputSignal,
}

/// Builder for [`Benchmark`].
///
/// | setting | default | valid |
/// |---|---|---|
/// | `n_samples` | 1000 | >= 1 |
/// | `input` | white Gaussian N(0, 1) per experiment | any [`InputSignal`] |
///
/// A run without noise is the run's condition, as for every simulator
/// (`Conditions::noiseless`, or the model wrapped in [`crate::NoiseFree`]).
#[derive(Debug, Clone)]
pub struct BenchmarkBuilder {
    n_samples: usize,
    input: Option<InputSignal>,
}

impl BenchmarkBuilder {
    /// Record length N.
    pub fn n_samples(mut self, n: usize) -> Self {
        self.n_samples = n;
        self
    }
    /// Replace the white-noise input.
    pub fn input(mut self, input: InputSignal) -> Self {
        self.input = Some(input);
        self
    }
    /// Check the settings and build the model.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] if `n_samples` is 0.
    pub fn build(self) -> Result<Benchmark> {
        let input = match self.input {
            Some(input) => input,
            None => InputSignal::white_gaussian(1.0)?,
        };
        let noise = format!(
            "process v11, v12 ~ WGN(0, {PROCESS_NOISE_VARIANCE}); measurement v2 ~ WGN(0, {MEASUREMENT_NOISE_VARIANCE})"
        );
        let spec = ModelSpec::new(
            "benchmark",
            &["theta"],
            Prior::uniform_box(&[-0.9], &[0.9])?,
            1.0,
            self.n_samples,
        )?
        .with_notes(&input.describe(), &noise);
        Ok(Benchmark { spec, input })
    }
}

impl Benchmark {
    /// The paper's setting: N = 1000, noisy, `u ~ WGN(0, 1)`.
    pub fn new() -> Self {
        Self::builder()
            .build()
            .unwrap_or_else(|e| unreachable!("the default benchmark settings are valid: {e}"))
    }

    /// A builder starting from the paper's settings.
    pub fn builder() -> BenchmarkBuilder {
        BenchmarkBuilder {
            n_samples: BENCHMARK_SAMPLES,
            input: None,
        }
    }

    /// The coefficients `(a, b)` of `x2(k+1) = a x1 - theta x2 + b u`:
    /// `a = (1 - theta^2) sin(50 theta^2)`, `b = theta / (1 + theta^2)`.
    pub fn coefficients(theta: f64) -> (f64, f64) {
        let t2 = theta * theta;
        ((1.0 - t2) * (50.0 * t2).sin(), theta / (1.0 + t2))
    }
}

impl Default for Benchmark {
    fn default() -> Self {
        Self::new()
    }
}

impl Simulator for Benchmark {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            noiseless: true,
            given_input: true,
        }
    }

    fn shared_input(&self) -> Option<IoData> {
        self.input.shared_record(&self.spec)
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()> {
        check_theta(&self.spec, theta)?;
        let n = conditions.check_input(&self.spec)?;
        let th = theta[0];
        let (a, b) = Self::coefficients(th);

        out.resize(n, 1, 1);
        let (u, y) = out.siso_mut();
        match conditions.input {
            Some(given) => u.copy_from_slice(given.input(0)),
            None => self.input.fill(1.0, rng, u)?,
        }
        let noisy = !conditions.noiseless;
        let measurement_sd = MEASUREMENT_NOISE_VARIANCE.sqrt();
        let process_sd = PROCESS_NOISE_VARIANCE.sqrt();
        let (mut x1, mut x2) = (0.0f64, 0.0f64);
        for k in 0..n {
            let (v2, v11, v12) = if noisy {
                let v2: f64 = StandardNormal.sample(rng);
                let v11: f64 = StandardNormal.sample(rng);
                let v12: f64 = StandardNormal.sample(rng);
                (measurement_sd * v2, process_sd * v11, process_sd * v12)
            } else {
                (0.0, 0.0, 0.0)
            };
            y[k] = x2 + v2;
            let next1 = 0.5 * x1 + u[k] + v11;
            let next2 = a * x1 - th * x2 + b * u[k] + v12;
            x1 = next1;
            x2 = next2;
            if !(x1.is_finite() && x2.is_finite()) {
                return Err(SimError::Diverged {
                    theta: theta.to_vec(),
                    time: (k + 1) as f64,
                });
            }
        }
        Ok(())
    }
}
