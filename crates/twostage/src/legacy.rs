//! What older estimator files store, and how each becomes today's
//! [`Estimator`]. Postcard is not self-describing: a version's layout is
//! read with that version's structs, then carried forward one version at
//! a time, so each step says only what its version added.

use serde::Deserialize;
use twostage_models::Marginal;
use twostage_validate::{ConformalIntervals, HoeffdingBound, ParameterReport, ValidationReport};

use crate::adaptive::AdaptiveIntervals;
use crate::envelope::FeatureEnvelope;
use crate::error::FileError;
use crate::estimator::{Estimator, EstimatorFields, RecordShape, SignalNames, TrainingInfo};
use twostage_compress::CompressorConfig;
use twostage_fit::FittedRegressor;

/// A parameter's validation before format version 4: no betting
/// certificate.
#[derive(Deserialize)]
pub(crate) struct ParameterReportV3 {
    name: String,
    mse: f64,
    rmse: f64,
    bias: f64,
    r2: f64,
    max_abs_error: f64,
    hoeffding: HoeffdingBound,
    interval_half_width: Option<f64>,
    interval_coverage: Option<f64>,
}

/// The validation report before format version 4.
#[derive(Deserialize)]
pub(crate) struct ValidationReportV3 {
    parameters: Vec<ParameterReportV3>,
    total: HoeffdingBound,
    intervals: Option<ConformalIntervals>,
}

impl From<ValidationReportV3> for ValidationReport {
    fn from(r: ValidationReportV3) -> Self {
        Self {
            parameters: r
                .parameters
                .into_iter()
                .map(|p| ParameterReport {
                    name: p.name,
                    mse: p.mse,
                    rmse: p.rmse,
                    bias: p.bias,
                    r2: p.r2,
                    max_abs_error: p.max_abs_error,
                    hoeffding: p.hoeffding,
                    certified: None,
                    interval_half_width: p.interval_half_width,
                    interval_coverage: p.interval_coverage,
                })
                .collect(),
            total: r.total,
            certified_total: None,
            intervals: r.intervals,
        }
    }
}

/// Format version 3: today's fields with the older validation report.
#[derive(Deserialize)]
pub(crate) struct EstimatorFieldsV3 {
    param_names: Vec<String>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    shape: RecordShape,
    compressor: CompressorConfig,
    regressor: FittedRegressor,
    training: TrainingInfo,
    intervals: Option<ConformalIntervals>,
    validation: Option<ValidationReportV3>,
    envelope: Option<FeatureEnvelope>,
    adaptive: Option<AdaptiveIntervals>,
    marginals: Vec<Marginal>,
    signal_names: Option<SignalNames>,
}

impl TryFrom<EstimatorFieldsV3> for Estimator {
    type Error = FileError;
    fn try_from(f: EstimatorFieldsV3) -> Result<Self, FileError> {
        Self::try_from(EstimatorFields {
            param_names: f.param_names,
            lower: f.lower,
            upper: f.upper,
            shape: f.shape,
            compressor: f.compressor,
            regressor: f.regressor,
            training: f.training,
            intervals: f.intervals,
            validation: f.validation.map(ValidationReport::from),
            envelope: f.envelope,
            adaptive: f.adaptive,
            marginals: f.marginals,
            signal_names: f.signal_names,
        })
    }
}

/// Format version 2: version 3 without the marginals (every prior uniform)
/// and the signal names.
#[derive(Deserialize)]
pub(crate) struct EstimatorFieldsV2 {
    param_names: Vec<String>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    shape: RecordShape,
    compressor: CompressorConfig,
    regressor: FittedRegressor,
    training: TrainingInfo,
    intervals: Option<ConformalIntervals>,
    validation: Option<ValidationReportV3>,
    envelope: Option<FeatureEnvelope>,
    adaptive: Option<AdaptiveIntervals>,
}

impl TryFrom<EstimatorFieldsV2> for Estimator {
    type Error = FileError;
    fn try_from(f: EstimatorFieldsV2) -> Result<Self, FileError> {
        let marginals = f
            .lower
            .iter()
            .zip(&f.upper)
            .map(|(&low, &high)| Marginal::Uniform { low, high })
            .collect();
        Self::try_from(EstimatorFieldsV3 {
            param_names: f.param_names,
            lower: f.lower,
            upper: f.upper,
            shape: f.shape,
            compressor: f.compressor,
            regressor: f.regressor,
            training: f.training,
            intervals: f.intervals,
            validation: f.validation,
            envelope: f.envelope,
            adaptive: f.adaptive,
            marginals,
            signal_names: None,
        })
    }
}

/// Format version 1: version 2 without the feature envelope and the
/// adaptive intervals.
#[derive(Deserialize)]
pub(crate) struct EstimatorFieldsV1 {
    param_names: Vec<String>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    shape: RecordShape,
    compressor: CompressorConfig,
    regressor: FittedRegressor,
    training: TrainingInfo,
    intervals: Option<ConformalIntervals>,
    validation: Option<ValidationReportV3>,
}

impl TryFrom<EstimatorFieldsV1> for Estimator {
    type Error = FileError;
    fn try_from(f: EstimatorFieldsV1) -> Result<Self, FileError> {
        Self::try_from(EstimatorFieldsV2 {
            param_names: f.param_names,
            lower: f.lower,
            upper: f.upper,
            shape: f.shape,
            compressor: f.compressor,
            regressor: f.regressor,
            training: f.training,
            intervals: f.intervals,
            validation: f.validation,
            envelope: None,
            adaptive: None,
        })
    }
}
