//! The Pacejka car of Section 6 of the paper, exactly as fixed by
//! spec/pacejka-car.md: single-track lateral and yaw dynamics with four
//! wheels, roll, load shift and Pacejka's magic formula, integrated by RK4.

use crate::InvalidSetting;
use rand_distr::{Distribution, StandardNormal};

use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::input::InputSignal;
use crate::ode::{OdeSystem, Rk4};
use crate::prior::Prior;
use crate::rng::ExperimentRng;
use crate::simulator::{Capabilities, Conditions, ModelSpec, Simulator, check_theta};

/// Vehicle constants (spec/pacejka-car.md, "Constants").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vehicle {
    /// Mass m, kg.
    pub mass: f64,
    /// Yaw inertia J, kg m^2.
    pub yaw_inertia: f64,
    /// Centre of mass to front axle lf, m.
    pub lf: f64,
    /// Centre of mass to rear axle lr, m.
    pub lr: f64,
    /// Track width l, m.
    pub track: f64,
    /// Centre-of-mass height h, m.
    pub cg_height: f64,
    /// Gravity g, m/s^2.
    pub gravity: f64,
    /// Speed V, m/s.
    pub speed: f64,
    /// Roll inertia Jr, kg m^2.
    pub roll_inertia: f64,
    /// Roll damping Cr, N m s/rad.
    pub roll_damping: f64,
    /// Roll stiffness Kr, N m/rad.
    pub roll_stiffness: f64,
}

impl Vehicle {
    /// The mid-size car of the spec.
    pub const PAPER: Self = Self {
        mass: 1500.0,
        yaw_inertia: 2500.0,
        lf: 1.1,
        lr: 1.6,
        track: 1.5,
        cg_height: 0.5,
        gravity: 9.81,
        speed: 10.0,
        roll_inertia: 700.0,
        roll_damping: 5000.0,
        roll_stiffness: 80000.0,
    };

    /// Static load of each axle, `(N_f, N_r)`.
    pub fn axle_loads(&self) -> (f64, f64) {
        let weight = self.mass * self.gravity;
        let wheelbase = self.lf + self.lr;
        (weight * self.lr / wheelbase, weight * self.lf / wheelbase)
    }
}

/// Tire constants of Pacejka's magic formula; pK1 and pK2 are the unknown
/// parameters and are passed separately.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(missing_docs)] // the fields are the formula's own symbols
pub struct Tire {
    /// Nominal load Fz0, N.
    pub fz0: f64,
    /// Camber angle gamma, rad.
    pub camber: f64,
    pub p_c1: f64,
    pub p_d1: f64,
    pub p_d2: f64,
    pub p_d3: f64,
    pub p_e1: f64,
    pub p_e2: f64,
    pub p_e3: f64,
    pub p_e4: f64,
    pub p_h1: f64,
    pub p_h2: f64,
    pub p_h3: f64,
    pub p_v1: f64,
    pub p_v2: f64,
    pub p_v3: f64,
    pub p_v4: f64,
    pub p_k3: f64,
}

impl Tire {
    /// The tire of the spec (all four alike).
    pub const PAPER: Self = Self {
        fz0: 4000.0,
        camber: 0.0,
        p_c1: 1.3,
        p_d1: 1.0,
        p_d2: -0.1,
        p_d3: 0.0,
        p_e1: -0.5,
        p_e2: -0.2,
        p_e3: 0.0,
        p_e4: 0.0,
        p_h1: 0.0,
        p_h2: 0.0,
        p_h3: 0.0,
        p_v1: 0.0,
        p_v2: 0.0,
        p_v3: 0.0,
        p_v4: 0.0,
        p_k3: 0.0,
    };

    /// Lateral force of one wheel with load `q` and slip angle `alpha`,
    /// Pacejka's magic formula as printed in the paper (Section 6.1).
    ///
    /// ```
    /// use twostage_models::Tire;
    /// let t = Tire::PAPER;
    /// // Small slip: F = K alpha with K = pK1 Fz0 sin(2 atan(Q / (pK2 Fz0))).
    /// let (pk1, pk2, q, alpha) = (-35.0, -1.1, 4000.0, 1e-7);
    /// let k = pk1 * t.fz0 * (2.0 * (q / (pk2 * t.fz0)).atan()).sin();
    /// assert!((t.lateral_force(q, alpha, pk1, pk2) / (k * alpha) - 1.0).abs() < 1e-6);
    /// ```
    pub fn lateral_force(&self, q: f64, alpha: f64, p_k1: f64, p_k2: f64) -> f64 {
        let gamma = self.camber;
        let fz = (q - self.fz0) / self.fz0;
        let s_h = self.p_h1 + self.p_h2 * fz + self.p_h3 * gamma;
        let s_v = q * ((self.p_v1 + self.p_v2 * fz) + (self.p_v3 + self.p_v4 * fz) * gamma);
        let a = alpha + s_h;
        let c = self.p_c1;
        let mu = (self.p_d1 + self.p_d2 * fz) * (1.0 - self.p_d3 * gamma * gamma);
        let d = mu * q;
        let e = (self.p_e1 + self.p_e2 * fz) * (1.0 - (self.p_e3 + self.p_e4 * gamma) * sign(a));
        // sin(2 atan(x)) = 2x / (1 + x^2): the same value without two
        // transcendental calls, in the innermost loop of every car simulation.
        let x = q / (p_k2 * self.fz0);
        let k = p_k1 * self.fz0 * (2.0 * x / (1.0 + x * x)) * (1.0 - self.p_k3 * gamma.abs());
        let b = k / (c * d);
        let ba = b * a;
        d * (c * (ba - e * (ba - ba.atan())).atan()).sin() + s_v
    }
}

/// The paper's sign function: `sign(0) = 0`.
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

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
        .with_notes(&format!("{}; RK4, step 0.002 s", input.describe()), &noise);
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
            vehicle: &self.vehicle,
            tire: &self.tire,
            p_k1: theta[0],
            p_k2: theta[1],
            input: (!given).then_some(&self.input),
            samples: inputs,
            loads: self.vehicle.axle_loads(),
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
    vehicle: &'a Vehicle,
    tire: &'a Tire,
    p_k1: f64,
    p_k2: f64,
    /// The car's own input design; `None`: `samples` are a given input's.
    input: Option<&'a InputSignal>,
    samples: &'a [f64],
    /// Static axle loads (N_f, N_r).
    loads: (f64, f64),
}

impl CarDynamics<'_> {
    /// Total lateral force and yaw moment for steer `delta` and state `x`.
    fn force_and_moment(&self, delta: f64, x: &[f64]) -> (f64, f64) {
        let v = self.vehicle;
        let (beta, r, phi) = (x[0], x[1], x[2]);
        let alpha_f = delta - beta - v.lf * r / v.speed;
        let alpha_r = -beta + v.lr * r / v.speed;
        let shift = v.cg_height / v.track * phi.sin();
        let (left, right) = (0.5 - shift, 0.5 + shift);
        let (n_f, n_r) = self.loads;
        let force = |q: f64, alpha: f64| self.tire.lateral_force(q, alpha, self.p_k1, self.p_k2);
        let front = force(n_f * left, alpha_f) + force(n_f * right, alpha_f);
        let rear = force(n_r * left, alpha_r) + force(n_r * right, alpha_r);
        (front + rear, v.lf * front - v.lr * rear)
    }

    /// The steer at time t.
    fn steer(&self, t: f64) -> f64 {
        match self.input {
            Some(input) => input.value_at(t, PACEJKA_SAMPLE_TIME, self.samples),
            None => InputSignal::sampled_value_at(t, PACEJKA_SAMPLE_TIME, self.samples),
        }
    }

    /// Lateral acceleration a_y at time t and state x.
    fn lateral_acceleration(&self, t: f64, x: &[f64]) -> f64 {
        let delta = self.steer(t);
        self.force_and_moment(delta, x).0 / self.vehicle.mass
    }
}

impl OdeSystem for CarDynamics<'_> {
    fn dim(&self) -> usize {
        4
    }

    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
        let v = self.vehicle;
        let delta = self.steer(t);
        let (force, moment) = self.force_and_moment(delta, x);
        let a_y = force / v.mass;
        let (r, phi, p) = (x[1], x[2], x[3]);
        dx[0] = a_y / v.speed - r; // m V (beta' + r) = sum F
        dx[1] = moment / v.yaw_inertia;
        dx[2] = p;
        let hm = v.cg_height * v.mass;
        dx[3] = (hm * v.gravity * phi.sin() + a_y * hm * phi.cos()
            - v.roll_damping * p
            - v.roll_stiffness * phi)
            / v.roll_inertia;
    }
}

impl Simulator for PacejkaCar {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate(&self, theta: &[f64], rng: &mut ExperimentRng, out: &mut IoData) -> Result<()> {
        self.simulate_under(theta, rng, Conditions::default(), out)
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

    fn simulate_under(
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
