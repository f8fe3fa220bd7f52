//! What a decoded estimator is checked for: each component has checked
//! its own invariants while decoding; these are the ones between
//! components, so that a decoded estimator estimates (or errs) and never
//! indexes out of range.

use twostage_compress::Compressor;
use twostage_fit::Predictor;

use crate::error::FileError;
use crate::estimator::Estimator;
use crate::layout::{EstimatorFields, Stages, V1, V2, V3, V5, V6, V9, V10};

impl TryFrom<EstimatorFields> for Estimator {
    type Error = FileError;
    /// Each component has checked its own invariants while decoding;
    /// this adds the ones between components, so that a decoded estimator
    /// estimates (or errs) and never indexes out of range.
    fn try_from(f: EstimatorFields) -> std::result::Result<Self, FileError> {
        let V10 {
            v9:
                V9 {
                    v6:
                        V6 {
                            v5: V5 { v4, input_family },
                            input_shapes,
                        },
                    posterior,
                },
            fixed,
        } = f;
        let V3 {
            v2:
                V2 {
                    v1:
                        V1 {
                            stages:
                                Stages {
                                    param_names,
                                    lower,
                                    upper,
                                    shape,
                                    compressor,
                                    regressor,
                                    training,
                                },
                            intervals,
                            validation,
                        },
                    envelope,
                    adaptive,
                },
            marginals,
            signal_names,
        } = v4;
        let estimator = Self {
            param_names,
            lower,
            upper,
            shape,
            compressor,
            regressor,
            training,
            intervals,
            validation,
            envelope,
            adaptive,
            marginals,
            signal_names,
            input_family,
            input_shapes,
            posterior,
            fixed,
            reported: None,
        };
        estimator
            .check_parameters()
            .and_then(|()| estimator.check_components())
            .map_err(|what| FileError::Inconsistent { what })?;
        Ok(estimator)
    }
}

impl Estimator {
    /// The parameters' names, boxes and priors agree.
    fn check_parameters(&self) -> std::result::Result<(), String> {
        let (param_names, lower, upper) = (&self.param_names, &self.lower, &self.upper);
        let q = param_names.len();
        if q == 0 || lower.len() != q || upper.len() != q {
            return Err(format!(
                "{q} parameter names, {} lower and {} upper bounds",
                lower.len(),
                upper.len()
            ));
        }
        if let Some(j) =
            (0..q).find(|&j| !(lower[j].is_finite() && upper[j].is_finite() && lower[j] < upper[j]))
        {
            return Err(format!(
                "the box [{}, {}] of {}",
                lower[j], upper[j], param_names[j]
            ));
        }
        if self.marginals.len() != q {
            return Err(format!(
                "{} priors for {q} parameters",
                self.marginals.len()
            ));
        }
        for (j, marginal) in self.marginals.iter().enumerate() {
            if marginal.check(j).is_err() {
                return Err(format!("the prior {marginal:?} of {}", param_names[j]));
            }
            // The box is the prior's range; a clip outside it would leave
            // the support (a log-normal's estimate must stay > 0).
            let (low, high) = marginal.range();
            let slack = 1e-9 * (high - low);
            if !(lower[j] >= low - slack && upper[j] <= high + slack) {
                return Err(format!(
                    "the box [{}, {}] of {} outside its prior's range [{low}, {high}]",
                    lower[j], upper[j], param_names[j]
                ));
            }
        }
        // A parameter held at a value is not one the estimator estimates.
        if let Some(held) = self
            .fixed
            .values()
            .iter()
            .find(|v| param_names.contains(&v.name) || !v.value.is_finite())
        {
            return Err(format!(
                "{} held at {} and estimated too",
                held.name, held.value
            ));
        }
        Ok(())
    }

    /// The stages, the envelope, the adaptive intervals, the signal names
    /// and the intervals fit each other and the parameters.
    fn check_components(&self) -> std::result::Result<(), String> {
        let q = self.param_names.len();
        let (compressor, regressor, shape) = (&self.compressor, &self.regressor, &self.shape);
        if regressor.n_outputs() != q || regressor.n_inputs() != compressor.n_features() {
            return Err(format!(
                "stage 2 maps {} features to {} parameters, stage 1 gives {} features for {q}",
                regressor.n_inputs(),
                regressor.n_outputs(),
                compressor.n_features()
            ));
        }
        if let Some(posterior) = &self.posterior {
            crate::posterior::check_against(posterior, compressor.n_features(), &self.marginals)?;
        }
        if let Some(envelope) = &self.envelope
            && envelope.dim() != compressor.n_features()
        {
            return Err(format!(
                "a feature envelope of {} features for {}",
                envelope.dim(),
                compressor.n_features()
            ));
        }
        if let Some(adaptive) = &self.adaptive
            && (adaptive.dim() != q || adaptive.n_features() != compressor.n_features())
        {
            return Err(format!(
                "adaptive intervals for {} parameters and {} features",
                adaptive.dim(),
                adaptive.n_features()
            ));
        }
        if let Some(names) = &self.signal_names
            && (names.inputs.len() != shape.n_inputs || names.outputs.len() != shape.n_outputs)
        {
            return Err(format!(
                "{} input and {} output names for records of {} and {}",
                names.inputs.len(),
                names.outputs.len(),
                shape.n_inputs,
                shape.n_outputs
            ));
        }
        if let Some(family) = &self.input_family
            && !family.is_consistent(shape.n_inputs)
        {
            return Err(format!(
                "an input family of {} signals for records of {} inputs",
                family.n_inputs(),
                shape.n_inputs
            ));
        }
        if let Some(shapes) = &self.input_shapes
            && shapes.n_inputs() != shape.n_inputs
        {
            return Err(format!(
                "input shapes of {} signals for records of {} inputs",
                shapes.n_inputs(),
                shape.n_inputs
            ));
        }
        if let Some(intervals) = &self.intervals {
            let widths = intervals.half_widths();
            if widths.len() != q || widths.iter().any(|w| w.is_nan() || *w < 0.0) {
                return Err(format!(
                    "interval half-widths {widths:?} for {q} parameters"
                ));
            }
        }
        Ok(())
    }
}
