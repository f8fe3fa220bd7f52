//! What estimator files store, version by version, and how each becomes
//! today's. Postcard is not self-describing, and it writes a nested struct
//! as its fields in order: each version's layout is the previous one's
//! nested, plus what the version added, so every field is named once.
//! A file is read with its version's layout, carried forward one version
//! at a time, and checked as a whole into an [`Estimator`](crate::Estimator).

use serde::Deserialize;
use twostage_models::{FixedValues, InputFamily, InputShapes, Marginal};
use twostage_validate::{ConformalIntervals, HoeffdingBound, ParameterReport, ValidationReport};

use crate::adaptive::AdaptiveIntervals;
use crate::envelope::FeatureEnvelope;
use crate::stored::{SignalNames, TrainingInfo};
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedMixture, FittedRegressor};
use twostage_models::RecordShape;

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

/// What every version stores first: the two stages and what they were
/// trained on.
#[derive(Deserialize)]
pub(crate) struct Stages {
    pub(crate) param_names: Vec<String>,
    pub(crate) lower: Vec<f64>,
    pub(crate) upper: Vec<f64>,
    pub(crate) shape: RecordShape,
    pub(crate) compressor: CompressorConfig,
    pub(crate) regressor: FittedRegressor,
    pub(crate) training: TrainingInfo,
}

/// Format version 1: the stages, the conformal intervals and the
/// validation report (`R`, the report's layout of the version).
#[derive(Deserialize)]
pub(crate) struct V1<R> {
    pub(crate) stages: Stages,
    pub(crate) intervals: Option<ConformalIntervals>,
    pub(crate) validation: Option<R>,
}

/// Format version 2 adds the feature envelope and the adaptive intervals.
#[derive(Deserialize)]
pub(crate) struct V2<R> {
    pub(crate) v1: V1<R>,
    pub(crate) envelope: Option<FeatureEnvelope>,
    pub(crate) adaptive: Option<AdaptiveIntervals>,
}

/// Format version 3 adds each parameter's prior and the signal names;
/// version 4, today's, has the same layout with a report that carries
/// certificates.
#[derive(Deserialize)]
pub(crate) struct V3<R> {
    pub(crate) v2: V2<R>,
    pub(crate) marginals: Vec<Marginal>,
    pub(crate) signal_names: Option<SignalNames>,
}

/// Format version 5 adds the family of inputs the held-out records
/// spanned.
#[derive(Deserialize)]
pub(crate) struct V5 {
    pub(crate) v4: V3<ValidationReport>,
    pub(crate) input_family: Option<InputFamily>,
}

/// Format version 6 adds the density of the held-out records' input
/// shapes (versions 7 and 8 share its layout).
#[derive(Deserialize)]
pub(crate) struct V6 {
    pub(crate) v5: V5,
    pub(crate) input_shapes: Option<InputShapes>,
}

/// Format version 9 adds the parameters' conditional density.
#[derive(Deserialize)]
pub(crate) struct V9 {
    pub(crate) v6: V6,
    pub(crate) posterior: Option<FittedMixture>,
}

/// Format version 10 adds the parameters held at values; today's layout.
#[derive(Deserialize)]
pub(crate) struct V10 {
    pub(crate) v9: V9,
    pub(crate) fixed: FixedValues,
}

/// Today's layout (format version 10).
pub(crate) type EstimatorFields = V10;

impl From<V9> for V10 {
    /// Nothing held.
    fn from(v9: V9) -> Self {
        Self {
            v9,
            fixed: FixedValues::default(),
        }
    }
}

impl From<V6> for V10 {
    /// No conditional density, nothing held.
    fn from(v6: V6) -> Self {
        V9::from(v6).into()
    }
}

impl From<V6> for V9 {
    /// No conditional density.
    fn from(v6: V6) -> Self {
        Self {
            v6,
            posterior: None,
        }
    }
}

impl From<V5> for V10 {
    /// No input shapes, no conditional density, nothing held.
    fn from(v5: V5) -> Self {
        V6::from(v5).into()
    }
}

impl From<V5> for V6 {
    /// No input shapes.
    fn from(v5: V5) -> Self {
        Self {
            v5,
            input_shapes: None,
        }
    }
}

impl From<V3<ValidationReport>> for V5 {
    /// No input family.
    fn from(v4: V3<ValidationReport>) -> Self {
        Self {
            v4,
            input_family: None,
        }
    }
}

impl From<V1<ValidationReportV3>> for V2<ValidationReportV3> {
    /// No envelope, no adaptive intervals.
    fn from(v1: V1<ValidationReportV3>) -> Self {
        Self {
            v1,
            envelope: None,
            adaptive: None,
        }
    }
}

impl From<V2<ValidationReportV3>> for V3<ValidationReportV3> {
    /// Every prior uniform on the box; the generic signal names.
    fn from(v2: V2<ValidationReportV3>) -> Self {
        let stages = &v2.v1.stages;
        let marginals = stages
            .lower
            .iter()
            .zip(&stages.upper)
            .map(|(&low, &high)| Marginal::Uniform { low, high })
            .collect();
        Self {
            v2,
            marginals,
            signal_names: None,
        }
    }
}

impl From<V3<ValidationReportV3>> for V3<ValidationReport> {
    /// The report without certificates.
    fn from(v3: V3<ValidationReportV3>) -> Self {
        let V3 {
            v2:
                V2 {
                    v1:
                        V1 {
                            stages,
                            intervals,
                            validation,
                        },
                    envelope,
                    adaptive,
                },
            marginals,
            signal_names,
        } = v3;
        Self {
            v2: V2 {
                v1: V1 {
                    stages,
                    intervals,
                    validation: validation.map(ValidationReport::from),
                },
                envelope,
                adaptive,
            },
            marginals,
            signal_names,
        }
    }
}
