//! What a model is: its name, parameters (each the plant's or a
//! record's own), prior, sampling and signals.

use crate::InvalidSetting;
use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::prior::Prior;

/// What a model is: its name, parameters, prior box, sampling and signals.
///
/// ```
/// use twostage_models::{ModelSpec, Prior};
/// let spec = ModelSpec::new("spring", &["k", "c"], Prior::uniform_box(&[1.0, 0.1], &[5.0, 1.0])?, 0.01, 800)?
///     .with_signals(&["force"], &["position"])
///     .with_notes("a step of 1 N at t = 0", "position noise of variance 1e-4");
/// assert_eq!(spec.param_names(), ["k", "c"]);
/// assert_eq!(spec.n_samples(), 800);
/// // 800 samples 1e306 apart would end past the largest f64.
/// let prior = Prior::uniform_box(&[1.0], &[5.0])?;
/// assert!(ModelSpec::new("far", &["k"], prior.clone(), 1e306, 800).is_err());
/// assert!(ModelSpec::new("far", &["k"], prior, 1e300, 800).is_ok());
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    name: String,
    param_names: Vec<String>,
    prior: Prior,
    sample_time: f64,
    n_samples: usize,
    input_names: Vec<String>,
    output_names: Vec<String>,
    input_note: String,
    noise_note: String,
    car_equations: Option<CarEquations>,
    /// Per parameter, whether it belongs to one record (an initial state,
    /// a sensor offset) rather than to the plant.
    per_record: Vec<bool>,
}

/// The equations of a model that the kernels hold, for a stage 1 that
/// linearizes them (`linearized`): the car's constants and its output
/// noise's variance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarEquations {
    /// The car's constants.
    pub car: twostage_kernels::pacejka::Car,
    /// The variance of its output's measurement noise.
    pub noise_variance: f64,
}

impl ModelSpec {
    /// A SISO model (`u`, `y`) with the given parameters, prior box, sampling
    /// time and record length.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] if the
    /// names do not match the prior's dimension, the sampling time is not
    /// finite and positive, the record is empty, or its last sample's time
    /// is beyond the largest `f64`.
    pub fn new(
        name: &str,
        param_names: &[&str],
        prior: Prior,
        sample_time: f64,
        n_samples: usize,
    ) -> Result<Self> {
        if param_names.len() != prior.dim() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "parameter names",
                value: param_names.join(","),
                reason: format!("the prior box has {} parameters", prior.dim()),
            }));
        }
        if !(sample_time.is_finite() && sample_time > 0.0) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "sample time",
                value: sample_time.to_string(),
                reason: "must be finite and > 0".into(),
            }));
        }
        if n_samples == 0 {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "number of samples",
                value: "0".into(),
                reason: "a record needs at least one sample".into(),
            }));
        }
        if !(n_samples as f64 * sample_time).is_finite() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "sample time",
                value: sample_time.to_string(),
                reason: format!(
                    "{n_samples} samples this far apart end beyond the largest time a \
                     number holds; give at most {:e}",
                    f64::MAX / n_samples as f64
                ),
            }));
        }
        Ok(Self {
            name: name.to_string(),
            param_names: param_names.iter().map(|s| s.to_string()).collect(),
            prior,
            sample_time,
            n_samples,
            input_names: vec!["u".into()],
            output_names: vec!["y".into()],
            input_note: String::new(),
            noise_note: String::new(),
            car_equations: None,
            per_record: vec![false; param_names.len()],
        })
    }

    /// Name the input and output signals (and so set their number).
    pub fn with_signals(mut self, inputs: &[&str], outputs: &[&str]) -> Self {
        self.input_names = inputs.iter().map(|s| s.to_string()).collect();
        self.output_names = outputs.iter().map(|s| s.to_string()).collect();
        self
    }

    /// Describe the input and the noise for people.
    pub fn with_notes(mut self, input: &str, noise: &str) -> Self {
        self.input_note = input.to_string();
        self.noise_note = noise.to_string();
        self
    }

    /// The same model, whose equations are the car's `equations` (its
    /// parameters pK1 and pK2, in that order).
    pub fn with_car_equations(mut self, equations: CarEquations) -> Self {
        self.car_equations = Some(equations);
        self
    }

    /// The same model, whose parameters marked `true` in `per_record`
    /// (one flag per parameter, in order) each belong to one record (an
    /// initial state, a sensor offset) rather than to the plant: a fit of
    /// several records together gives each record its own value of them.
    ///
    /// ```
    /// use twostage_models::{ModelSpec, Prior};
    /// let prior = Prior::uniform_box(&[0.1, 0.0], &[2.0, 5.0])?;
    /// let spec = ModelSpec::new("tank", &["a", "h0"], prior, 1.0, 100)?
    ///     .with_per_record(&[false, true])?;
    /// assert_eq!(spec.per_record(), [false, true]);
    /// assert!(spec.with_per_record(&[true]).is_err());
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// A flag count other than the parameters'.
    pub fn with_per_record(mut self, per_record: &[bool]) -> Result<Self> {
        if per_record.len() != self.param_names.len() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "per-record parameters",
                value: format!("{} flags", per_record.len()),
                reason: format!("the model has {} parameters", self.param_names.len()),
            }));
        }
        self.per_record = per_record.to_vec();
        Ok(self)
    }

    /// Per parameter, whether it belongs to one record rather than to the
    /// plant ([`ModelSpec::with_per_record`]; all `false` unless set).
    pub fn per_record(&self) -> &[bool] {
        &self.per_record
    }

    /// The same model with the parameters `free` (by place) of `prior`
    /// (those left by [`crate::WithFixed`]), without the car's equations
    /// (of both).
    pub(crate) fn with_parameters(&self, free: &[usize], prior: Prior) -> Self {
        Self {
            param_names: free.iter().map(|&j| self.param_names[j].clone()).collect(),
            per_record: free.iter().map(|&j| self.per_record[j]).collect(),
            prior,
            car_equations: None,
            ..self.clone()
        }
    }

    /// The car's equations, when the model is the car.
    pub fn car_equations(&self) -> Option<&CarEquations> {
        self.car_equations.as_ref()
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// The parameter names, in the order of theta.
    pub fn param_names(&self) -> &[String] {
        &self.param_names
    }
    /// The prior box.
    pub fn prior(&self) -> &Prior {
        &self.prior
    }
    /// Number of parameters q.
    pub fn n_params(&self) -> usize {
        self.param_names.len()
    }
    /// Time between samples (1 for discrete-time models).
    pub fn sample_time(&self) -> f64 {
        self.sample_time
    }
    /// Record length N.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }
    /// Names of the input signals.
    pub fn input_names(&self) -> &[String] {
        &self.input_names
    }
    /// Names of the output signals.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }
    /// How the input is generated.
    pub fn input_note(&self) -> &str {
        &self.input_note
    }
    /// What noise enters the experiment.
    pub fn noise_note(&self) -> &str {
        &self.noise_note
    }
    /// The shape of this model's records: samples, signals, sampling
    /// time.
    pub fn record_shape(&self) -> crate::RecordShape {
        crate::RecordShape {
            n_samples: self.n_samples,
            n_inputs: self.input_names.len(),
            n_outputs: self.output_names.len(),
            sample_time: self.sample_time,
        }
    }

    /// A zero record of this model's shape.
    pub fn new_record(&self) -> IoData {
        IoData::zeros(
            self.n_samples,
            self.input_names.len(),
            self.output_names.len(),
        )
    }
}
