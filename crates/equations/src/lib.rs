//! Models written as equations: states with initial values, their
//! derivatives (continuous time, integrated by the fixed-step RK4 of the
//! models crate, its arithmetic compiled with the equations)
//! or next values (discrete time), named intermediate
//! quantities and outputs, over the model's parameters, inputs and the
//! time `t`. Each right side is parsed once by
//! [exmex](https://docs.rs/exmex) and the equations of a
//! step compiled to machine code by
//! [Cranelift](https://docs.rs/cranelift-jit); a record
//! then costs only the model's own arithmetic.
//!
//! ```
//! use twostage_equations::{Equation, EquationModel, EquationsText, State, Time};
//! use twostage_models::{IoData, ModelSpec, Prior};
//!
//! // A first-order lag x' = (k u - x) / tau, measured as y = x.
//! let prior = Prior::uniform_box(&[0.5, 1.0], &[2.0, 3.0])?;
//! let spec = ModelSpec::new("lag", &["k", "tau"], prior, 0.1, 50)?.with_signals(&["u"], &["y"]);
//! let text = EquationsText {
//!     time: Time::Continuous { substeps: 10 },
//!     states: vec![State::new("x", "0", "(k * u - x) / tau")],
//!     definitions: vec![],
//!     outputs: vec![Equation::new("y", "x")],
//!     ..EquationsText::default()
//! };
//! let model = EquationModel::compile(&text, &spec)?;
//! let mut record = IoData::zeros(50, 1, 1);
//! record.input_mut(0).fill(1.0);
//! model.respond(&[2.0, 1.5], &mut record, None)?;
//! // The step response k (1 - exp(-t / tau)) at t = 4.9 s.
//! let exact = 2.0 * (1.0 - (-4.9f64 / 1.5).exp());
//! assert!((record.output(0)[49] - exact).abs() < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod expression;
mod instruction;
mod integrator;
mod jit;
mod model;
mod ops;
mod simulator;

pub use model::EquationModel;
pub use simulator::EquationSimulator;

/// Continuous or discrete time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Time {
    /// States follow derivatives, integrated by RK4 in `substeps` equal
    /// steps per sample.
    Continuous {
        /// RK4 steps per sample interval (at least 1).
        substeps: usize,
    },
    /// States follow next-state equations, one step per sample.
    Discrete,
}

impl Default for Time {
    fn default() -> Self {
        Self::Continuous { substeps: 10 }
    }
}

/// When within a sample interval the outputs are measured.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Measure {
    /// Sample k at its start, t = k T, before the states move on (the
    /// first sample sees the initial state).
    #[default]
    Start,
    /// Sample k at its end, t = (k + 1) T (the first sample one interval
    /// after the initial state, as many simulators record).
    End,
}

/// How a continuous-time model's states are integrated between samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Integrator {
    /// The classic fourth-order Runge-Kutta method (the models crate's).
    #[default]
    Rk4,
    /// Euler's explicit method: x += h f(t, x), as many simple simulators
    /// step (to reproduce one exactly).
    Euler,
}

/// What the inputs are between samples, for a continuous-time model.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum InputPath {
    /// The cubic through the four nearest samples where the signal is
    /// smooth, straight where it holds or at its ends, held after the
    /// last ([`twostage_models::InputSignal::sampled_value_at`], as the
    /// built-in car sees a sampled steer).
    #[default]
    Cubic,
    /// The straight line through the samples, held after the last (the
    /// chord: what earlier versions read).
    Linear,
    /// Each sample held until the next (a zero-order hold: a digital
    /// controller's output, a pump switched per sample).
    Hold,
}

impl InputPath {
    /// The sampled signal `samples` at time `t` (a held path reads it
    /// sample by sample elsewhere: here as the cubic one).
    pub(crate) fn value_at(self, t: f64, sample_time: f64, samples: &[f64]) -> f64 {
        match self {
            Self::Linear => twostage_models::InputSignal::linear_value_at(t, sample_time, samples),
            Self::Cubic | Self::Hold => {
                twostage_models::InputSignal::sampled_value_at(t, sample_time, samples)
            }
        }
    }
}

/// A named right side: `name = text`.
#[derive(Debug, Clone, PartialEq)]
pub struct Equation {
    /// The name it defines.
    pub name: String,
    /// Its right side.
    pub text: String,
    /// Where it was written (a line of the model file), for messages.
    pub line: Option<usize>,
}

impl Equation {
    /// `name = text`.
    pub fn new(name: &str, text: &str) -> Self {
        Self {
            name: name.to_string(),
            text: text.to_string(),
            line: None,
        }
    }
}

/// A state: its initial value (an expression of the parameters and the
/// states before it), its derivative or next value, and its process noise.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Its name.
    pub name: String,
    /// Its value at t = 0.
    pub initial: String,
    /// Its derivative (continuous time) or next value (discrete time).
    pub update: String,
    /// Standard deviation of its process noise: of a Wiener increment per
    /// unit time (continuous: each RK4 step of length h adds sd sqrt(h)
    /// times a standard normal draw), or of the noise added at each step
    /// (discrete). 0 for none.
    pub noise_sd: f64,
    /// Where it was written (a line of the model file), for messages.
    pub line: Option<usize>,
}

impl State {
    /// A noise-free state.
    pub fn new(name: &str, initial: &str, update: &str) -> Self {
        Self {
            name: name.to_string(),
            initial: initial.to_string(),
            update: update.to_string(),
            noise_sd: 0.0,
            line: None,
        }
    }
}

/// A model's equations as written, before they are compiled.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EquationsText {
    /// Continuous or discrete time.
    pub time: Time,
    /// When the outputs are measured within a sample interval.
    pub measure: Measure,
    /// How a continuous-time model's states are integrated.
    pub integrator: Integrator,
    /// What the inputs are between samples (continuous time).
    pub inputs: InputPath,
    /// The states, in order (an initial value may use those before it).
    pub states: Vec<State>,
    /// Named intermediate quantities, in any order (cycles are refused).
    pub definitions: Vec<Equation>,
    /// One equation per output of the model, named as it.
    pub outputs: Vec<Equation>,
    /// Per output (in the model's order), the standard deviation of
    /// multiplicative log-normal noise: y times exp(sd z), z standard
    /// normal. Empty or 0 for none.
    pub lognormal_sd: Vec<f64>,
}

/// What is wrong with an equation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{equation}{}: {message}", position.map_or_else(String::new, |p| format!(", at character {}", p + 1)))]
pub struct EquationError {
    /// Which equation (`x.derivative`, `y`, ...).
    pub equation: String,
    /// Where in its text, from 0, where known.
    pub position: Option<usize>,
    /// What is wrong, and what to do.
    pub message: String,
}

/// The names an equation may read, each with its slot in the value
/// table: `t`, then parameters, inputs, states and defined quantities
/// (intermediates, then outputs).
#[derive(Debug, Clone)]
pub(crate) struct Names {
    names: Vec<String>,
    /// First slot of each group: parameters, inputs, states, defined.
    starts: [usize; 4],
}

/// The slot of the time `t`.
pub(crate) const TIME_SLOT: usize = 0;

impl Names {
    pub(crate) fn new(
        parameters: &[String],
        inputs: &[String],
        states: &[String],
        defined: &[String],
    ) -> Self {
        let mut names = vec!["t".to_string()];
        let mut starts = [0; 4];
        for (g, group) in [parameters, inputs, states, defined].iter().enumerate() {
            starts[g] = names.len();
            names.extend(group.iter().cloned());
        }
        Self { names, starts }
    }

    pub(crate) fn slot(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    pub(crate) fn len(&self) -> usize {
        self.names.len()
    }

    pub(crate) fn name(&self, slot: usize) -> &str {
        &self.names[slot]
    }

    pub(crate) fn parameters(&self) -> std::ops::Range<usize> {
        self.starts[0]..self.starts[1]
    }

    pub(crate) fn inputs(&self) -> std::ops::Range<usize> {
        self.starts[1]..self.starts[2]
    }

    pub(crate) fn states(&self) -> std::ops::Range<usize> {
        self.starts[2]..self.starts[3]
    }

    pub(crate) fn defined(&self) -> std::ops::Range<usize> {
        self.starts[3]..self.names.len()
    }

    /// The known names, for a message.
    pub(crate) fn known(&self) -> String {
        self.names.join(", ")
    }
}
