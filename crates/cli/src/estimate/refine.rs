//! Refining an estimate through the model: a built-in model's local
//! posterior, or an output-error fit through any other's simulator.

use anyhow::Result;
use twostage::fit::TerminationReason;
use twostage::models::{BuiltinModel, IoData, Simulator};
use twostage::{Estimator, ModelProfile, OutputError, Refinement};

use super::EstimateArgs;
use crate::usage;

/// Refines a TS estimate of one record from the estimate and the record's
/// interval half-widths: the refined estimate and, for a descent, why it
/// stopped.
pub(super) type Refine =
    Box<dyn Fn(&IoData, &[f64], Option<&[f64]>) -> Result<Refined, String> + Send + Sync>;

/// A refined estimate.
pub(super) struct Refined {
    pub(super) theta: Vec<f64>,
    /// Why the output-error descent stopped (`None` for the posterior mean).
    pub(super) stop: Option<TerminationReason>,
    /// The refined estimate's own interval half-widths, at the level of the
    /// estimator's intervals, or why it has none.
    pub(super) half_widths: Result<Vec<f64>, String>,
    /// The parameters' correlation matrix (row-major), where the interval
    /// has one.
    pub(super) correlation: Option<Vec<f64>>,
}

/// The refinement of an estimator's estimates: a built-in model's local
/// posterior (over twice its calibrated interval, the model's own grid),
/// or for any other model an output-error fit through its simulator.
pub(super) fn refinement(estimator: &Estimator, args: &EstimateArgs) -> Result<Refine> {
    let radius = estimator
        .neighbourhood(2.0)
        .map_err(|e| usage(format!("--refine: {e}")))?;
    // A neighbourhood exists only where the estimator has intervals.
    let alpha = estimator.intervals().map_or(0.1, |i| i.alpha());
    if args.model_file.is_none()
        && let Ok(model) = estimator.training().model.parse::<BuiltinModel>()
    {
        let points = ModelProfile::of(model).refinement_points();
        let local = Refinement::new(twostage_baselines::exact_likelihood(model)?);
        return Ok(Box::new(move |record: &IoData, start: &[f64], _| {
            // The posterior's own spread: its sd, under a normal
            // approximation at the intervals' level.
            let posterior = local
                .local_posterior(record, start, &radius, points)
                .map_err(|e| e.to_string())?;
            let z = twostage::models::standard_normal_quantile(1.0 - alpha / 2.0);
            Ok(Refined {
                half_widths: Ok(posterior.sd.iter().map(|s| z * s).collect()),
                correlation: Some(posterior.correlation),
                theta: posterior.mean,
                stop: None,
            })
        }));
    }
    let fit = Refinement::new(
        OutputError::new(model_of(estimator, args)?)
            .map_err(|e| usage(format!("--refine: {e}")))?,
    );
    Ok(Box::new(
        move |record: &IoData, start: &[f64], widths: Option<&[f64]>| {
            // The record's own interval where it has one (adaptive).
            let widths =
                widths.map_or_else(|| radius.iter().map(|r| r / 2.0).collect(), <[f64]>::to_vec);
            let descents = fit
                .descents_from(record, refine_starts(start, &widths))
                .map_err(|e| e.to_string())?;
            let best = descents
                .into_iter()
                .reduce(|best, d| if d.loss < best.loss { d } else { best })
                .ok_or_else(|| "no start".to_string())?;
            // Its own uncertainty, from the loss's curvature there and the
            // residuals' variance and autocorrelation.
            let local = fit
                .uncertainty(record, &best.theta)
                .map_err(|e| e.to_string());
            Ok(Refined {
                theta: best.theta,
                stop: Some(best.stop),
                half_widths: local
                    .as_ref()
                    .map(|u| u.half_widths(alpha))
                    .map_err(Clone::clone),
                correlation: local.ok().map(|u| u.correlation),
            })
        },
    ))
}

/// Where an output-error refinement starts: the estimate, and two corners
/// of half its interval on either side (alternating signs across the
/// parameters), so that a start lies off each axis the estimate may be
/// wrong along. The descents are bounded by the prior, not the interval:
/// on a real record the model's best fit may lie outside an interval
/// calibrated on the model's own records.
pub(super) fn refine_starts(estimate: &[f64], half_widths: &[f64]) -> Vec<Vec<f64>> {
    let corner = |sign: f64| -> Vec<f64> {
        estimate
            .iter()
            .zip(half_widths)
            .enumerate()
            .map(|(j, (t, w))| {
                let alternate = if j % 2 == 0 { 1.0 } else { -1.0 };
                t + sign * alternate * 0.5 * w
            })
            .collect()
    };
    vec![estimate.to_vec(), corner(1.0), corner(-1.0)]
}

/// The model an estimator's records come from, to check them against:
/// `--model-file`, else the estimator's built-in model.
pub(super) fn model_of(estimator: &Estimator, args: &EstimateArgs) -> Result<Box<dyn Simulator>> {
    let named = match &args.model_file {
        Some(path) => twostage::NamedModel::file(path).map_err(|e| usage(e.to_string()))?,
        None => twostage::NamedModel::builtin(&estimator.training().model).map_err(|_| {
            usage(format!(
                "--check simulates the model: this estimator is of '{}', give its \
                 --model-file",
                estimator.training().model
            ))
        })?,
    };
    if named.name() != estimator.training().model {
        return Err(usage(format!(
            "--model-file describes '{}', the estimator was trained on '{}': give the model \
             file it was trained from",
            named.name(),
            estimator.training().model
        )));
    }
    named.simulator(false).map_err(|e| usage(e.to_string()))
}
