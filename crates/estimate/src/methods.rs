//! How a request estimates one record: every way of estimating answers
//! with the same typed row.

use twostage_baselines::{PredictionError, RecordEstimator};
use twostage_estimator::Estimator;
use twostage_models::IoData;
use twostage_refine::OutputError;

use super::GivenValues;
use super::failure::MethodFailure;
use super::refiner::RefinedBy;
use super::rows::{RecordEstimate, RefineOutcome, Refined};
use crate::SharedSimulator;

/// The name the multi-start output-error fit goes by among the methods.
pub const OUTPUT_ERROR_METHOD: &str = "oe";

/// A way of estimating one record.
pub(super) enum Method {
    /// A trained estimator; `any_length`: a record of another length than
    /// its training records' is estimated too (a refinement or the joint
    /// fit starts from its estimate and fits the record at its length).
    TwoStage {
        estimator: Box<Estimator>,
        any_length: bool,
    },
    /// A classic method of a built-in model.
    Classic(Box<dyn RecordEstimator>),
    /// The multi-start output-error fit.
    OutputError(Box<PredictionError<OutputError<SharedSimulator>>>),
    /// Given values.
    Given(GivenValues),
}

impl Method {
    pub(super) fn two_stage(estimator: Box<Estimator>, any_length: bool) -> Self {
        Self::TwoStage {
            estimator,
            any_length,
        }
    }

    /// The multi-start output-error fit through `simulator`: `starts`
    /// draws from the prior of `seed`.
    pub(super) fn output_error(
        simulator: SharedSimulator,
        starts: usize,
        seed: u64,
    ) -> Result<Self, twostage_refine::RefineError> {
        let fit = OutputError::new(simulator)?;
        Ok(Self::OutputError(Box::new(
            PredictionError::new(fit, starts)
                .seed(seed)
                .named(OUTPUT_ERROR_METHOD),
        )))
    }

    /// The estimate of experiment `id`'s `record`, or why there is none.
    pub(super) fn estimate(
        &self,
        id: &str,
        record: &IoData,
    ) -> Result<RecordEstimate, MethodFailure> {
        match self {
            Self::TwoStage {
                estimator,
                any_length,
            } => {
                if let Some(refusal) = estimator.length_refusal(record.n_samples())
                    && !any_length
                {
                    return Err(MethodFailure::Length(refusal));
                }
                let a = estimator.assess(record)?;
                // The adaptive intervals have the same level and follow the
                // record; the fixed ones are the fallback. Both were
                // calibrated for the two-stage estimate, not a refined one.
                Ok(RecordEstimate {
                    distance: a.feature_distance.zip(a.distance_threshold),
                    half_widths: a.interval_half_widths().map(<[f64]>::to_vec),
                    input: estimator
                        .input_family()
                        .is_some()
                        .then_some(a.input_deviations),
                    input_shape: a.input_shape_distance.zip(a.input_shape_threshold),
                    floored: estimator.transforms_outputs().then_some(a.floored_samples),
                    ..RecordEstimate::bare(a.theta)
                })
            }
            Self::Classic(method) => method
                .estimate(record)
                .map(|e| RecordEstimate::bare(e.theta))
                .map_err(MethodFailure::from),
            Self::OutputError(fit) => {
                let best = fit
                    .descents(record)?
                    .into_iter()
                    .next()
                    .ok_or(MethodFailure::NoDescent)?;
                Ok(RecordEstimate {
                    refinement: Some(RefineOutcome::Done(Refined {
                        by: RefinedBy::Descent {
                            stop: best.stop,
                            optima: None,
                        },
                        interval_failure: None,
                        correlation: None,
                    })),
                    ..RecordEstimate::bare(best.theta)
                })
            }
            Self::Given(given) => given
                .of(id)
                .map(RecordEstimate::bare)
                .map_err(MethodFailure::from),
        }
    }
}
