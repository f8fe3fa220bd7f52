//! A Duffing-type oscillator whose output-error loss has several basins,
//! for the tests of searches that must not stop in the wrong one.

// Each test binary uses its own share of these.
#![allow(dead_code)]

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{
    Capabilities, Conditions, ExperimentRng, IoData, ModelSpec, Prior, SimError, Simulator,
    experiment_rng,
};

/// Samples of a record.
pub const N: usize = 800;
/// Sample time, s.
pub const DT: f64 = 0.1;
/// Output noise sd.
pub const NOISE: f64 = 0.02;

/// `x'' + c x' + k x + k3 x^3 = u`, `y = x + e`, RK4 with two steps a
/// sample and the input held between samples; as a plant, with a
/// quadratic stiffness `k2 x^2` the model leaves out.
pub struct Duffing {
    spec: ModelSpec,
    unmodelled: f64,
}

impl Duffing {
    pub fn new() -> Self {
        let prior = Prior::uniform_box(&[0.5, 0.02, 0.0], &[6.0, 0.4, 3.0]).unwrap();
        let spec = ModelSpec::new("duffing", &["k", "c", "k3"], prior, DT, N)
            .unwrap()
            .with_signals(&["u"], &["y"]);
        Self {
            spec,
            unmodelled: 0.0,
        }
    }

    /// The plant with a quadratic stiffness `k2` besides the model's terms.
    pub fn with_unmodelled(k2: f64) -> Self {
        Self {
            unmodelled: k2,
            ..Self::new()
        }
    }

    fn respond(&self, theta: &[f64], u: &[f64], noise: Option<&mut ExperimentRng>, y: &mut [f64]) {
        let (k, c, k3, k2) = (theta[0], theta[1], theta[2], self.unmodelled);
        let f = |x: f64, v: f64, u: f64| (v, u - c * v - k * x - k2 * x * x - k3 * x * x * x);
        let (mut x, mut v) = (0.0, 0.0);
        let h = DT / 2.0;
        for (t, u) in u.iter().enumerate() {
            y[t] = x;
            for _ in 0..2 {
                let (a1, b1) = f(x, v, *u);
                let (a2, b2) = f(x + 0.5 * h * a1, v + 0.5 * h * b1, *u);
                let (a3, b3) = f(x + 0.5 * h * a2, v + 0.5 * h * b2, *u);
                let (a4, b4) = f(x + h * a3, v + h * b3, *u);
                x += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
                v += h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4);
            }
        }
        if let Some(rng) = noise {
            for y in y.iter_mut() {
                let e: f64 = StandardNormal.sample(rng);
                *y += NOISE * e;
            }
        }
    }
}

impl Simulator for Duffing {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            noiseless: true,
            given_input: true,
        }
    }
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        let input = conditions
            .input
            .ok_or(SimError::InvalidData("no input".into()))?;
        let n = input.n_samples();
        out.resize(n, 1, 1);
        out.input_mut(0).copy_from_slice(input.input(0));
        let u = input.input(0).to_vec();
        // A simulator that refuses what it cannot integrate.
        if let Some(t) = u.iter().position(|v| v.abs() > 100.0) {
            return Err(SimError::InvalidData(format!(
                "input sample {t} is beyond the actuator's 100"
            )));
        }
        let noise = (!conditions.noiseless).then_some(rng);
        self.respond(theta, &u, noise, out.output_mut(0));
        Ok(())
    }
}

/// A multisine of three tones through the oscillator's band.
pub fn input() -> Vec<f64> {
    input_of(0)
}

/// The multisine of [`input`] with its phases shifted by experiment `i`.
pub fn input_of(i: u64) -> Vec<f64> {
    let shift = i as f64;
    (0..N)
        .map(|t| {
            let s = t as f64 * DT;
            (0.7 * s + 0.9 * shift).sin()
                + 0.8 * (1.9 * s + 1.0 + 2.3 * shift).sin()
                + 0.6 * (3.1 * s + 2.0 + 4.1 * shift).sin()
        })
        .collect()
}

/// The record of plant `theta` with its output noise, stream `i`.
pub fn record(model: &Duffing, theta: &[f64], i: u64) -> IoData {
    record_on(model, theta, &input(), i)
}

/// The record of plant `theta` on input `u` with its output noise, stream `i`.
pub fn record_on(model: &Duffing, theta: &[f64], u: &[f64], i: u64) -> IoData {
    let given = IoData::siso(u, &vec![0.0; u.len()]).unwrap();
    let mut out = IoData::default();
    let noisy = Conditions {
        noiseless: false,
        input: Some(&given),
    };
    model
        .simulate_under(theta, &mut experiment_rng(91, i), noisy, &mut out)
        .unwrap();
    out
}
