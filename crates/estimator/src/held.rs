//! An estimator some of whose parameters are held at values at estimate
//! time: it reports the others, and its model holds the values wherever
//! it is simulated (a check, a refinement, a joint fit), as an estimator
//! trained with them held does.

use twostage_models::{FixedValues, ModelSpec, Prior};

use crate::error::Result;
use crate::estimator::Estimator;

impl Estimator {
    /// The same estimator with the parameters of `values` held there: it
    /// reports the other parameters only (stage 2's own estimates of them,
    /// which did not know the held values), and its [`Estimator::fixed`]
    /// holds these besides any it was trained with, so that a refinement
    /// through its model searches the others alone. It has no posterior
    /// and no validation report (both were of every parameter), and it is
    /// not saved: train with the values held to keep them in a file.
    ///
    /// ```
    /// use twostage::models::{FixedValues, PacejkaCar};
    /// use twostage::TwoStage;
    /// let car = PacejkaCar::builder().n_samples(100).build()?;
    /// let estimator = TwoStage::builder(&car)
    ///     .simulations(200).validation(0).calibration(50).seed(1).linear(1e-6)?.train()?;
    /// let held = estimator.holding(&FixedValues::parse(&["pK2=-1.1"])?)?;
    /// assert_eq!(held.param_names(), ["pK1"]);
    /// assert_eq!(held.fixed().to_string(), "pK2 = -1.1");
    /// // pK1's estimate is the whole estimator's.
    /// let mut record = twostage::models::Simulator::spec(&car).new_record();
    /// twostage::models::Simulator::simulate(&car, &[-30.0, -1.1], &mut twostage::models::experiment_rng(2, 0), &mut record)?;
    /// assert_eq!(held.estimate_record(&record)?[0], estimator.estimate_record(&record)?[0]);
    /// // Unknown names are refused with the names there are.
    /// let unknown = estimator.holding(&FixedValues::parse(&["mass=1500"])?).unwrap_err();
    /// assert!(unknown.to_string().contains("pK1, pK2"), "{unknown}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// A name the estimator does not estimate (its names listed), a value
    /// outside its parameter's prior, or every parameter held (nothing
    /// left to estimate).
    pub fn holding(&self, values: &FixedValues) -> Result<Self> {
        if values.is_empty() {
            return Ok(self.clone());
        }
        // The model file's rules for held values, on this estimator's
        // parameters and priors.
        let names: Vec<&str> = self.param_names.iter().map(String::as_str).collect();
        let prior = Prior::new(self.marginals.clone())?;
        let spec = ModelSpec::new(&self.training.model, &names, prior, 1.0, 1)?;
        let held = values.positions(&spec)?;
        let kept: Vec<usize> = (0..names.len()).filter(|j| !held.contains(j)).collect();
        let pick = |v: &[f64]| -> Vec<f64> { kept.iter().map(|&j| v[j]).collect() };
        let mut fixed = self.fixed.values().to_vec();
        fixed.extend(values.values().iter().cloned());
        let fixed = FixedValues::from_pairs(fixed.iter().map(|f| (f.name.as_str(), f.value)))?;
        let reported = match &self.reported {
            Some(reported) => kept.iter().map(|&j| reported[j]).collect(),
            None => kept.clone(),
        };
        Ok(Self {
            param_names: kept.iter().map(|&j| self.param_names[j].clone()).collect(),
            lower: pick(&self.lower),
            upper: pick(&self.upper),
            marginals: kept.iter().map(|&j| self.marginals[j]).collect(),
            intervals: self.intervals.as_ref().map(|c| c.of_parameters(&kept)),
            validation: None,
            posterior: None,
            fixed,
            reported: Some(reported),
            ..self.clone()
        })
    }

    /// Whether some of its parameters are held at estimate time
    /// ([`Estimator::holding`]).
    pub fn holds_at_estimate_time(&self) -> bool {
        self.reported.is_some()
    }
}
