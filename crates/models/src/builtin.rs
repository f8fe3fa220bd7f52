//! The built-in models by name, for command lines and configuration files.

use std::fmt;
use std::str::FromStr;

use crate::benchmark::Benchmark;
use crate::error::{Result, SimError};
use crate::input::InputSignal;
use crate::pacejka::PacejkaCar;
use crate::simulator::Simulator;

/// The models that ship with twostage.
///
/// ```
/// use twostage_models::BuiltinModel;
/// let model: BuiltinModel = "pacejka".parse()?;
/// let car = model.build()?;
/// assert_eq!(car.param_names(), ["pK1", "pK2"]);
/// assert!("tractor".parse::<BuiltinModel>().is_err());
/// # Ok::<(), twostage_models::SimError>(())
/// ```
// Not `#[non_exhaustive]` on purpose: every table keyed by the built-in
// models (presets, classic methods) must say what a new model offers, and
// an exhaustive `match` makes the compiler ask (docs/decisions/014).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BuiltinModel {
    /// The benchmark system of eq. (5).
    Benchmark,
    /// The Pacejka car of Section 6.
    Pacejka,
}

impl BuiltinModel {
    /// Every built-in model.
    pub const ALL: [Self; 2] = [Self::Benchmark, Self::Pacejka];

    /// The model's name as typed by users.
    pub fn name(self) -> &'static str {
        match self {
            Self::Benchmark => "benchmark",
            Self::Pacejka => "pacejka",
        }
    }

    /// A one-line description.
    pub fn summary(self) -> &'static str {
        match self {
            Self::Benchmark => {
                "the paper's benchmark, eq. (5): a second-order linear system whose \
                 coefficients depend on theta through sin(50 theta^2)"
            }
            Self::Pacejka => {
                "the paper's car (Section 6, spec/pacejka-car.md): lateral, yaw and roll \
                 dynamics with Pacejka tires, steered along a chicane at 10 m/s"
            }
        }
    }

    /// Build the model with the paper's settings (its noise; a run
    /// without it is the run's condition, [`crate::NoiseFree`]).
    ///
    /// # Errors
    /// Never for the built-in settings; the `Result` keeps the door open for
    /// models whose construction can fail.
    pub fn build(self) -> Result<Box<dyn Simulator>> {
        self.build_with(&BuiltinOverrides::default())
    }

    /// Build the model with some of the paper's settings replaced (what a
    /// model file with a built-in source may change).
    ///
    /// ```
    /// use twostage_models::{BuiltinModel, BuiltinOverrides, InputSignal};
    /// let short = BuiltinModel::Benchmark.build_with(&BuiltinOverrides {
    ///     n_samples: Some(200),
    ///     input: Some(InputSignal::white_gaussian(2.0)?),
    ///     ..BuiltinOverrides::default()
    /// })?;
    /// assert_eq!(short.spec().n_samples(), 200);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// A record length or input the model's builder refuses.
    pub fn build_with(self, overrides: &BuiltinOverrides) -> Result<Box<dyn Simulator>> {
        let model: Box<dyn Simulator> = match self {
            Self::Benchmark => {
                let mut b = Benchmark::builder();
                if let Some(n) = overrides.n_samples {
                    b = b.n_samples(n);
                }
                if let Some(input) = &overrides.input {
                    b = b.input(input.clone());
                }
                Box::new(b.build()?)
            }
            Self::Pacejka => {
                let mut b = PacejkaCar::builder();
                if let Some(n) = overrides.n_samples {
                    b = b.n_samples(n);
                }
                if let Some(input) = &overrides.input {
                    b = b.input(input.clone());
                }
                Box::new(b.build()?)
            }
        };
        if overrides.noiseless {
            return Ok(Box::new(crate::NoiseFree::new(model)?));
        }
        Ok(model)
    }
}

/// The settings of a built-in model that may be replaced; `None` keeps the
/// paper's.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BuiltinOverrides {
    /// Drop the model's own process and measurement noise (a model file's
    /// `[noise] model = false`): the model runs as [`crate::NoiseFree`]
    /// runs it.
    pub noiseless: bool,
    /// Samples per record.
    pub n_samples: Option<usize>,
    /// The input of every experiment.
    pub input: Option<InputSignal>,
}

impl fmt::Display for BuiltinModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for BuiltinModel {
    type Err = SimError;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| SimError::UnknownModel {
                name: s.to_string(),
                known: Self::ALL.map(|m| m.name()).join(", "),
            })
    }
}
