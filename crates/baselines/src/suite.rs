//! The classic methods of each built-in model, built from the per-model
//! table of the facade ([`twostage::ModelProfile`]): the table says which
//! methods exist for a model and with which settings, this module binds each
//! (model, method) pair to its implementation.

use twostage_models::{Benchmark, BuiltinModel, PacejkaCar};
use twostage_refine::ResidualModel;
use twostage_sources::{ClassicMethod, ModelProfile};

use crate::error::{BaselineError, Result};
use crate::{
    BayesBenchmark, BayesCar, BenchmarkParticles, BenchmarkPredictor, CarParticles, CarPredictor,
    IndirectInference, InitialCovariance, KalmanEstimator, ParticleFilter, PredictionError,
    RecordEstimator,
};

/// The per-run settings of a classic method (the per-model ones are in the
/// table).
///
/// | setting | default | used by |
/// |---|---|---|
/// | `initial_covariance` | [`InitialCovariance::Eq6`] | EKF, UKF |
/// | `particles` | the model's (1000 benchmark, 500 car) | particle filter |
/// | `starts` | 5 | prediction error, indirect inference |
/// | `seed` | 0 | the random methods |
#[derive(Debug, Clone, PartialEq)]
pub struct MethodSettings {
    /// The Kalman filters' initial covariance (the paper's eq. (6) or (7)).
    pub initial_covariance: InitialCovariance,
    /// Particles; `None` takes the model's default.
    pub particles: Option<usize>,
    /// Random starts.
    pub starts: usize,
    /// Seed of the random choices.
    pub seed: u64,
}

impl Default for MethodSettings {
    fn default() -> Self {
        Self {
            initial_covariance: InitialCovariance::Eq6,
            particles: None,
            starts: 5,
            seed: 0,
        }
    }
}

/// `method` for `model`, ready to estimate records.
///
/// ```
/// use twostage::ClassicMethod;
/// use twostage::models::BuiltinModel;
/// use twostage_baselines::{MethodSettings, classic_estimator};
/// let pem = classic_estimator(BuiltinModel::Pacejka, ClassicMethod::PredictionError, &MethodSettings::default())?;
/// assert_eq!(pem.name(), "pem5");
/// // The car has no Kalman filter in the paper: refused, not replaced.
/// let e = classic_estimator(BuiltinModel::Pacejka, ClassicMethod::Ekf, &MethodSettings::default());
/// assert!(e.is_err());
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
///
/// # Errors
/// [`BaselineError::NotAvailable`] for a method the model's table entry
/// does not list; a setting the method refuses.
pub fn classic_estimator(
    model: BuiltinModel,
    method: ClassicMethod,
    settings: &MethodSettings,
) -> Result<Box<dyn RecordEstimator>> {
    let profile = ModelProfile::of(model);
    // The table decides what exists; the match below only binds.
    let listed = profile.classic_methods();
    let not_available = || BaselineError::NotAvailable {
        method: method.name(),
        model: model.name(),
        available: listed
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>()
            .join(", "),
    };
    if !listed.contains(&method) {
        return Err(not_available());
    }
    let particles = settings.particles.unwrap_or(profile.default_particles());
    let (p0, starts, seed) = (settings.initial_covariance, settings.starts, settings.seed);
    Ok(match (model, method) {
        (BuiltinModel::Benchmark, ClassicMethod::Ekf) => Box::new(KalmanEstimator::ekf(p0)),
        (BuiltinModel::Benchmark, ClassicMethod::Ukf) => Box::new(KalmanEstimator::ukf(p0)),
        (BuiltinModel::Pacejka, ClassicMethod::Ekf | ClassicMethod::Ukf) => {
            // Not listed for the car: refused above already.
            return Err(not_available());
        }
        (BuiltinModel::Benchmark, ClassicMethod::ParticleFilter) => {
            Box::new(ParticleFilter::new(BenchmarkParticles::new()?, particles).seed(seed))
        }
        (BuiltinModel::Pacejka, ClassicMethod::ParticleFilter) => {
            Box::new(ParticleFilter::new(CarParticles::new(), particles).seed(seed))
        }
        (_, ClassicMethod::PredictionError) => {
            Box::new(PredictionError::new(exact_likelihood(model), starts).seed(seed))
        }
        (BuiltinModel::Benchmark, ClassicMethod::IndirectInference) => Box::new(
            IndirectInference::new(Benchmark::new(), profile.indirect_inference_arx(), starts)
                .seed(seed)
                .build()?,
        ),
        (BuiltinModel::Pacejka, ClassicMethod::IndirectInference) => Box::new(
            IndirectInference::new(PacejkaCar::new(), profile.indirect_inference_arx(), starts)
                .seed(seed)
                .build()?,
        ),
        (BuiltinModel::Benchmark, ClassicMethod::Bayes) => Box::new(BayesBenchmark::default()),
        (BuiltinModel::Pacejka, ClassicMethod::Bayes) => Box::new(BayesCar::paper()?),
    })
}

/// The model's exact prediction-error likelihood: the benchmark's Kalman
/// innovations, the car's noise-free simulation errors. What prediction
/// error minimizes and the local posterior refinement integrates.
///
pub fn exact_likelihood(model: BuiltinModel) -> Box<dyn ResidualModel<Error = BaselineError>> {
    match model {
        BuiltinModel::Benchmark => Box::new(BenchmarkPredictor::new()),
        BuiltinModel::Pacejka => Box::new(CarPredictor::new()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table and the binding agree: a listed method builds, an unlisted
    /// one is refused as not available (the car's grid Bayes reference is
    /// skipped: building it simulates the whole grid).
    #[test]
    fn every_listed_method_builds_and_no_other() {
        let settings = MethodSettings {
            starts: 1,
            ..MethodSettings::default()
        };
        for model in BuiltinModel::ALL {
            let listed = ModelProfile::of(model).classic_methods();
            for method in ClassicMethod::ALL {
                if (model, method) == (BuiltinModel::Pacejka, ClassicMethod::Bayes) {
                    continue;
                }
                let built = classic_estimator(model, method, &settings);
                if listed.contains(&method) {
                    assert!(built.is_ok(), "{model} {method}");
                } else {
                    let e = built.map(|_| ()).unwrap_err().to_string();
                    assert!(e.contains(&format!("not available for {model}")), "{e}");
                }
            }
        }
    }
}
