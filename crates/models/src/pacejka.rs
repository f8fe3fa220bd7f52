//! The Pacejka car of Section 6 of the paper, exactly as fixed by
//! spec/pacejka-car.md: single-track lateral and yaw dynamics with four
//! wheels, roll, load shift and Pacejka's magic formula, integrated by RK4.

use crate::InvalidSetting;
use rand_distr::{Distribution, StandardNormal};
pub use twostage_kernels::pacejka::{Car, Tire, Vehicle};

use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::input::InputSignal;
use crate::ode::{OdeSystem, Rk4};
use crate::prior::Prior;
use crate::rng::ExperimentRng;
use crate::simulator::{Capabilities, CarEquations, Conditions, ModelSpec, Simulator, check_theta};

/// Record length of the paper's experiment: 500 samples, 0 to 9.98 s.
pub const PACEJKA_SAMPLES: usize = 500;
/// Sampling period Ts, s.
pub const PACEJKA_SAMPLE_TIME: f64 = 0.02;
/// RK4 steps per sample (step 0.002 s).
pub const PACEJKA_STEPS_PER_SAMPLE: usize = 10;
/// Variance of the accelerometer noise, (m/s^2)^2.
pub const PACEJKA_NOISE_VARIANCE: f64 = 0.01;
/// Chicane amplitude, rad.
pub const CHICANE_AMPLITUDE: f64 = 0.2;

/// The car of the Pacejka example. Unknown parameters theta = (pK1, pK2) in
/// the box `[-42.83, -27.32] x [-1.22, -0.98]`; input the front steering
/// angle (the chicane by default), output the lateral acceleration with
/// white measurement noise of variance 0.01. State (beta, r, phi, p), all
/// zero at t = 0.
///
/// ```
/// use twostage_models::{experiment_rng, NoiseFree, PacejkaCar, Simulator};
/// let car = NoiseFree::new(Box::new(PacejkaCar::new()))?;
/// let mut record = car.spec().new_record();
/// car.simulate(&[-35.0, -1.1], &mut experiment_rng(0, 0), &mut record)?;
/// // pacejka-golden.csv: t = 6 s gives a_y = 5.98522057067 m/s^2.
/// assert!((record.output(0)[300] - 5.98522057067).abs() < 1e-6);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone)]
pub struct PacejkaCar {
    spec: ModelSpec,
    vehicle: Vehicle,
    tire: Tire,
    input: InputSignal,
}

/// Builder for [`PacejkaCar`].
///
/// | setting | default | valid |
/// |---|---|---|
/// | `n_samples` | 500 (0 to 9.98 s) | >= 1 |
/// | `input` | the chicane, A = 0.2 rad | any [`InputSignal`] |
/// | `vehicle`, `tire` | [`Vehicle::PAPER`], [`Tire::PAPER`] | physical values |
///
/// A run without the measurement noise is the run's condition, as for
/// every simulator (`Conditions::noiseless`, or the car wrapped in
/// [`crate::NoiseFree`]).
#[derive(Debug, Clone)]
pub struct PacejkaCarBuilder {
    n_samples: usize,
    input: Option<InputSignal>,
    vehicle: Vehicle,
    tire: Tire,
}

impl PacejkaCarBuilder {
    /// Record length N (samples every 0.02 s from t = 0).
    pub fn n_samples(mut self, n: usize) -> Self {
        self.n_samples = n;
        self
    }
    /// Replace the chicane by another steering input.
    pub fn input(mut self, input: InputSignal) -> Self {
        self.input = Some(input);
        self
    }
    /// Replace the vehicle constants.
    pub fn vehicle(mut self, vehicle: Vehicle) -> Self {
        self.vehicle = vehicle;
        self
    }
    /// Replace the tire constants.
    pub fn tire(mut self, tire: Tire) -> Self {
        self.tire = tire;
        self
    }
    /// Check the settings and build the model.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] if `n_samples` is 0 or a vehicle
    /// constant that divides (mass, inertias, speed, wheelbase, track,
    /// nominal load) is not finite and positive.
    pub fn build(self) -> Result<PacejkaCar> {
        let v = &self.vehicle;
        let positive = [
            ("mass", v.mass),
            ("yaw inertia", v.yaw_inertia),
            ("roll inertia", v.roll_inertia),
            ("speed", v.speed),
            ("wheelbase lf + lr", v.lf + v.lr),
            ("track", v.track),
            ("nominal load Fz0", self.tire.fz0),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(SimError::InvalidSetting(InvalidSetting {
                    name: "vehicle constant",
                    value: format!("{name} = {value}"),
                    reason: "must be finite and > 0".into(),
                }));
            }
        }
        let input = match self.input {
            Some(input) => input,
            None => InputSignal::chicane(CHICANE_AMPLITUDE)?,
        };
        let noise = format!(
            "white Gaussian on y, variance {PACEJKA_NOISE_VARIANCE} (m/s^2)^2; input noise-free"
        );
        let spec = ModelSpec::new(
            "pacejka",
            &["pK1", "pK2"],
            Prior::uniform_box(&[-42.83, -1.22], &[-27.32, -0.98])?,
            PACEJKA_SAMPLE_TIME,
            self.n_samples,
        )?
        .with_signals(&["delta"], &["a_y"])
        .with_notes(&format!("{}; RK4, step 0.002 s", input.describe()), &noise)
        .with_car_equations(CarEquations {
            car: Car {
                vehicle: self.vehicle,
                tire: self.tire,
            },
            noise_variance: PACEJKA_NOISE_VARIANCE,
        });
        Ok(PacejkaCar {
            spec,
            vehicle: self.vehicle,
            tire: self.tire,
            input,
        })
    }
}

impl PacejkaCar {
    /// The equations at `theta` on the sampled steer `inputs`; `given`:
    /// the samples are a given record's (interpolated between samples),
    /// not the car's own input design.
    fn dynamics<'a>(&'a self, theta: &[f64], inputs: &'a [f64], given: bool) -> CarDynamics<'a> {
        CarDynamics {
            car: Car {
                vehicle: self.vehicle,
                tire: self.tire,
            },
            theta: [theta[0], theta[1]],
            input: (!given).then_some(&self.input),
            samples: inputs,
        }
    }

    /// The noise-free lateral acceleration at sample `k` for the state
    /// `(beta, r, phi, p)` at time `k Ts`; `inputs` are the sampled steer
    /// (used between samples when the input is not the chicane).
    pub fn output_at(&self, theta: &[f64], k: usize, state: &[f64; 4], inputs: &[f64]) -> f64 {
        self.dynamics(theta, inputs, false)
            .lateral_acceleration(k as f64 * PACEJKA_SAMPLE_TIME, state)
    }

    /// Integrate the state from sample `k` to `k + 1` (ten RK4 steps of
    /// 0.002 s, numbered globally so every stage time is a multiple of the
    /// step). Filters and predictors step the car with this, exactly as
    /// [`Simulator::simulate`] does.
    pub fn advance(
        &self,
        theta: &[f64],
        k: usize,
        state: &mut [f64; 4],
        inputs: &[f64],
        rk4: &mut Rk4,
    ) {
        Self::step(&self.dynamics(theta, inputs, false), k, state, rk4);
    }

    fn step(dynamics: &CarDynamics<'_>, k: usize, state: &mut [f64; 4], rk4: &mut Rk4) {
        let h = PACEJKA_SAMPLE_TIME / PACEJKA_STEPS_PER_SAMPLE as f64;
        let first = k * PACEJKA_STEPS_PER_SAMPLE;
        for j in first..first + PACEJKA_STEPS_PER_SAMPLE {
            rk4.step(dynamics, j as f64 * h, h, state);
        }
    }

    /// The paper's setting: chicane, N = 500, noise variance 0.01.
    pub fn new() -> Self {
        Self::builder()
            .build()
            .unwrap_or_else(|e| unreachable!("the default car settings are valid: {e}"))
    }

    /// A builder starting from the spec's settings.
    pub fn builder() -> PacejkaCarBuilder {
        PacejkaCarBuilder {
            n_samples: PACEJKA_SAMPLES,
            input: None,
            vehicle: Vehicle::PAPER,
            tire: Tire::PAPER,
        }
    }

    /// The vehicle constants.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The tire constants.
    pub fn tire(&self) -> &Tire {
        &self.tire
    }
}

impl Default for PacejkaCar {
    fn default() -> Self {
        Self::new()
    }
}

/// The car's equations at one parameter vector, with one input realization.
struct CarDynamics<'a> {
    car: Car,
    theta: [f64; 2],
    /// The car's own input design; `None`: `samples` are a given input's.
    input: Option<&'a InputSignal>,
    samples: &'a [f64],
}

impl CarDynamics<'_> {
    /// The steer at time t.
    fn steer(&self, t: f64) -> f64 {
        match self.input {
            Some(input) => input.value_at(t, PACEJKA_SAMPLE_TIME, self.samples),
            None => InputSignal::sampled_value_at(t, PACEJKA_SAMPLE_TIME, self.samples),
        }
    }

    /// Lateral acceleration a_y at time t and state x.
    fn lateral_acceleration(&self, t: f64, x: &[f64; 4]) -> f64 {
        self.car.lateral_acceleration(self.theta, self.steer(t), x)
    }
}

impl OdeSystem for CarDynamics<'_> {
    fn dim(&self) -> usize {
        4
    }

    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
        let state = [x[0], x[1], x[2], x[3]];
        dx.copy_from_slice(&self.car.derivatives(self.theta, self.steer(t), &state));
    }
}

impl Simulator for PacejkaCar {
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

        out.resize(n, 1, 1);
        let (u, y) = out.siso_mut();
        match conditions.input {
            Some(given) => u.copy_from_slice(given.input(0)),
            None => self.input.fill(PACEJKA_SAMPLE_TIME, rng, u)?,
        }
        let dynamics = self.dynamics(theta, u, conditions.input.is_some());
        let mut rk4 = Rk4::new(4);
        let mut x = [0.0f64; 4];
        let noise_sd = if conditions.noiseless {
            0.0
        } else {
            PACEJKA_NOISE_VARIANCE.sqrt()
        };
        for (k, y_k) in y.iter_mut().enumerate() {
            if k > 0 {
                Self::step(&dynamics, k - 1, &mut x, &mut rk4);
                if x.iter().any(|v| !v.is_finite()) {
                    return Err(SimError::Diverged {
                        theta: theta.to_vec(),
                        time: k as f64 * PACEJKA_SAMPLE_TIME,
                    });
                }
            }
            let a_y = dynamics.lateral_acceleration(k as f64 * PACEJKA_SAMPLE_TIME, &x);
            if !a_y.is_finite() {
                return Err(SimError::Diverged {
                    theta: theta.to_vec(),
                    time: k as f64 * PACEJKA_SAMPLE_TIME,
                });
            }
            *y_k = a_y;
        }
        if noise_sd > 0.0 {
            for y_k in y.iter_mut() {
                let z: f64 = StandardNormal.sample(rng);
                *y_k += noise_sd * z;
            }
        }
        Ok(())
    }
}
