//! The per-model table: what each built-in model offers beyond simulation,
//! declared once. Presets of the two-stage pipeline, the paper's classic
//! methods that exist for it (with their per-model settings), and whether
//! an exact likelihood allows refining an estimate. The command line, the
//! paper reproduction and the benchmarks read it; a model without an entry
//! for something gets [`Error::NotAvailable`], never another model's.

use crate::InvalidSetting;
use std::fmt;
use std::str::FromStr;

use twostage_compress::Arx;
use twostage_fit::{MlpParams, Piecewise};
use twostage_models::BuiltinModel;

use crate::error::{Error, Result};
use crate::preset::Preset;
use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;

/// A classic estimation method of the paper (Sections 2 and 5), or an
/// exact reference, by its command-line name.
///
/// ```
/// use twostage_sources::ClassicMethod;
/// let pf: ClassicMethod = "pf".parse()?;
/// assert_eq!(pf, ClassicMethod::ParticleFilter);
/// assert!("kalman".parse::<ClassicMethod>().is_err());
/// # Ok::<(), twostage_sources::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClassicMethod {
    /// Extended Kalman filter on the state augmented with theta (`ekf`).
    Ekf,
    /// Unscented Kalman filter on the augmented state (`ukf`).
    Ukf,
    /// Particle filter (`pf`).
    ParticleFilter,
    /// Prediction error with random starts (`pem`).
    PredictionError,
    /// Indirect inference through the TS preset's ARX (`ii`).
    IndirectInference,
    /// The Bayes-optimal posterior mean on a grid (`bayes`): the accuracy
    /// limit the others are measured against.
    Bayes,
}

impl ClassicMethod {
    /// Every method, in the paper's order.
    pub const ALL: [Self; 6] = [
        Self::Ekf,
        Self::Ukf,
        Self::ParticleFilter,
        Self::PredictionError,
        Self::IndirectInference,
        Self::Bayes,
    ];

    /// The name users type.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ekf => "ekf",
            Self::Ukf => "ukf",
            Self::ParticleFilter => "pf",
            Self::PredictionError => "pem",
            Self::IndirectInference => "ii",
            Self::Bayes => "bayes",
        }
    }
}

impl fmt::Display for ClassicMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ClassicMethod {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                Error::InvalidSetting(InvalidSetting {
                    name: "method",
                    value: s.to_string(),
                    reason: format!("use one of {}", names(Self::ALL.iter().map(|m| m.name()))),
                })
            })
    }
}

/// A named preset: its name and the function that builds it.
type NamedPreset = (&'static str, fn() -> Preset);

/// One built-in model's entry in the table.
#[derive(Debug)]
pub struct ModelProfile {
    model: BuiltinModel,
    presets: &'static [NamedPreset],
    classic: &'static [ClassicMethod],
    particles: usize,
    indirect_arx: (usize, usize),
    refinement_points: usize,
}

/// The table, one entry per built-in model.
static PROFILES: [ModelProfile; 2] = [
    ModelProfile {
        model: BuiltinModel::Benchmark,
        presets: &[
            ("paper", paper_benchmark),
            ("recommended", recommended_benchmark),
        ],
        classic: &ClassicMethod::ALL,
        particles: 1000,
        indirect_arx: (5, 5),
        refinement_points: 45,
    },
    ModelProfile {
        model: BuiltinModel::Pacejka,
        presets: &[
            ("paper", paper_pacejka),
            ("recommended", recommended_pacejka),
        ],
        // The paper runs the Kalman filters on the benchmark only.
        classic: &[
            ClassicMethod::ParticleFilter,
            ClassicMethod::PredictionError,
            ClassicMethod::IndirectInference,
            ClassicMethod::Bayes,
        ],
        particles: 500,
        indirect_arx: (4, 4),
        refinement_points: 13,
    },
];

impl ModelProfile {
    /// The entry of a built-in model.
    ///
    /// ```
    /// use twostage_sources::{ClassicMethod, ModelProfile};
    /// use twostage_models::BuiltinModel;
    /// let car = ModelProfile::of(BuiltinModel::Pacejka);
    /// assert_eq!(car.preset("paper")?.simulations, 2000);
    /// assert!(car.classic_method("pem").is_ok());
    /// // Not "the benchmark's EKF": a clear refusal.
    /// let refused = car.classic_method("ekf").unwrap_err().to_string();
    /// assert!(refused.contains("not available for pacejka"), "{refused}");
    /// # Ok::<(), twostage_sources::Error>(())
    /// ```
    pub fn of(model: BuiltinModel) -> &'static ModelProfile {
        // Exhaustive: a new built-in model does not compile without its entry.
        match model {
            BuiltinModel::Benchmark => &PROFILES[0],
            BuiltinModel::Pacejka => &PROFILES[1],
        }
    }

    /// The model.
    pub fn model(&self) -> BuiltinModel {
        self.model
    }

    /// The names of the model's presets (`paper` first).
    pub fn preset_names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.presets.iter().map(|(name, _)| *name)
    }

    /// A preset by name.
    ///
    /// # Errors
    /// [`Error::NotAvailable`] naming the presets that exist.
    pub fn preset(&self, name: &str) -> Result<Preset> {
        self.presets
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, make)| make())
            .ok_or_else(|| self.not_available("preset", name, names(self.preset_names())))
    }

    /// The classic methods that exist for this model.
    pub fn classic_methods(&self) -> &'static [ClassicMethod] {
        self.classic
    }

    /// A classic method by name, if this model has it.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] for a name no model has,
    /// [`Error::NotAvailable`] for a method this model lacks.
    pub fn classic_method(&self, name: &str) -> Result<ClassicMethod> {
        let method: ClassicMethod = name.parse()?;
        if self.classic.contains(&method) {
            Ok(method)
        } else {
            Err(self.not_available("method", name, names(self.classic.iter().map(|m| m.name()))))
        }
    }

    /// The particle filter's default number of particles (the paper's:
    /// 1000 for the benchmark, 500 for the car).
    pub fn default_particles(&self) -> usize {
        self.particles
    }

    /// The auxiliary model of indirect inference: the paper preset's ARX.
    pub fn indirect_inference_arx(&self) -> Arx {
        let (na, nb) = self.indirect_arx;
        Arx::new(na, nb).unwrap_or_else(|e| unreachable!("the table's ARX orders are valid: {e}"))
    }

    /// Grid points per axis of the local posterior that refines a TS
    /// estimate with the model's exact likelihood (45 for one parameter,
    /// 13 for two: about 2,000 and 170 likelihood evaluations).
    pub fn refinement_points(&self) -> usize {
        self.refinement_points
    }

    fn not_available(&self, what: &'static str, name: &str, available: String) -> Error {
        Error::NotAvailable {
            what,
            name: name.to_string(),
            model: self.model.name().to_string(),
            available,
        }
    }
}

fn names<'a>(items: impl Iterator<Item = &'a str>) -> String {
    items.collect::<Vec<_>>().join(", ")
}

/// The paper's benchmark setting (Section 5.3): m = 1500 simulations,
/// ARX(5, 5), a network with 10 tanh hidden units.
pub fn paper_benchmark() -> Preset {
    arx_mlp(5, 10, 1500)
}

/// The paper's car setting (Section 6.2): m = 2000 simulations, ARX(4, 4), a
/// network with 20 tanh hidden units.
pub fn paper_pacejka() -> Preset {
    arx_mlp(4, 20, 2000)
}

/// What the automatic design chose for the benchmark (docs/accuracy.md):
/// ARX(2, 2), a global 20-unit network routing to 4 experts of 20 units
/// by pieces of theta's range, m = 16000 simulations.
pub fn recommended_benchmark() -> Preset {
    let mlp = MlpParams::new(&[20])
        .and_then(MlpParams::check)
        .unwrap_or_else(|e| unreachable!("a 20-unit network is valid: {e}"));
    let piecewise = Piecewise::new(mlp.clone(), mlp, 4)
        .unwrap_or_else(|e| unreachable!("4 pieces are valid: {e}"));
    Preset {
        compressor: CompressorConfig::Arx(arx(2)),
        regressor: RegressorConfig::Piecewise(piecewise),
        simulations: 16_000,
    }
}

/// What the automatic design chose for the car (docs/accuracy.md): ARX(2,
/// 2), whose two input lags are far less collinear on the chicane than
/// the paper's four, and a 10-unit network, m = 8000 simulations.
pub fn recommended_pacejka() -> Preset {
    arx_mlp(2, 10, 8000)
}

fn arx(order: usize) -> Arx {
    Arx::new(order, order).unwrap_or_else(|e| unreachable!("ARX({order}, {order}) is valid: {e}"))
}

fn arx_mlp(order: usize, hidden: usize, simulations: usize) -> Preset {
    let mlp = MlpParams::new(&[hidden])
        .and_then(MlpParams::check)
        .unwrap_or_else(|e| unreachable!("a {hidden}-unit network is valid: {e}"));
    Preset {
        compressor: CompressorConfig::Arx(arx(order)),
        regressor: RegressorConfig::Mlp(mlp),
        simulations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_model_has_its_own_entry() {
        for model in BuiltinModel::ALL {
            assert_eq!(ModelProfile::of(model).model(), model);
        }
        assert_eq!(PROFILES.len(), BuiltinModel::ALL.len());
    }

    #[test]
    fn presets_and_methods_are_the_models_own() {
        let bench = ModelProfile::of(BuiltinModel::Benchmark);
        let car = ModelProfile::of(BuiltinModel::Pacejka);
        assert_eq!(bench.preset("paper").unwrap(), paper_benchmark());
        assert_eq!(car.preset("paper").unwrap(), paper_pacejka());
        assert_ne!(paper_benchmark(), paper_pacejka());
        assert_eq!(car.preset("recommended").unwrap(), recommended_pacejka());
        assert_eq!(
            bench.preset("recommended").unwrap(),
            recommended_benchmark()
        );
        assert_eq!(
            bench.preset_names().collect::<Vec<_>>(),
            ["paper", "recommended"]
        );
        assert!(matches!(
            car.preset("fastest"),
            Err(Error::NotAvailable { what: "preset", .. })
        ));
        for m in ClassicMethod::ALL {
            assert_eq!(m.name().parse::<ClassicMethod>().unwrap(), m);
            assert!(bench.classic_method(m.name()).is_ok());
        }
        for refused in ["ekf", "ukf"] {
            match car.classic_method(refused) {
                Err(Error::NotAvailable {
                    model, available, ..
                }) => {
                    assert_eq!(model, "pacejka");
                    assert_eq!(available, "pf, pem, ii, bayes");
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(matches!(
            car.classic_method("kalman"),
            Err(Error::InvalidSetting(_))
        ));
        assert_eq!(car.indirect_inference_arx(), Arx::new(4, 4).unwrap());
        assert_eq!(
            (bench.default_particles(), car.default_particles()),
            (1000, 500)
        );
    }
}
