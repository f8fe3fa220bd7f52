//! The command line's side of refining and checking an estimator's
//! estimates: the model named on it (the refinement itself is
//! `twostage_baselines::EstimateRefiner`, shared with the Python package).

use anyhow::Result;
use twostage::models::Simulator;
use twostage::{Estimator, NamedModel};
use twostage_baselines::EstimateRefiner;

use super::EstimateArgs;
use crate::OrUsage;

/// The --model-file given, loaded.
fn model_file(args: &EstimateArgs) -> Result<Option<NamedModel>> {
    args.model_file
        .as_ref()
        .map(|path| NamedModel::file(path).or_usage())
        .transpose()
}

/// The refinement of an estimator's estimates (see
/// [`EstimateRefiner::new`]).
pub(super) fn refinement(estimator: &Estimator, args: &EstimateArgs) -> Result<EstimateRefiner> {
    let q = estimator.param_names().len();
    Ok(EstimateRefiner::new(estimator, model_file(args)?.as_ref())
        .usage_context("--refine")?
        .search(args.search(q)))
}

/// The model an estimator's records come from, to check them against:
/// `--model-file`, else the estimator's built-in model.
pub(super) fn model_of(estimator: &Estimator, args: &EstimateArgs) -> Result<Box<dyn Simulator>> {
    twostage_baselines::estimator_model(estimator, model_file(args)?.as_ref())
        .usage_context("--check simulates the model")
}

/// The joint fit of an estimator's records (see
/// [`twostage_baselines::JointFitter::new`]).
pub(super) fn joint_fitter(
    estimator: &Estimator,
    args: &EstimateArgs,
) -> Result<twostage_baselines::JointFitter> {
    let q = estimator.param_names().len();
    twostage_baselines::JointFitter::new(estimator, model_file(args)?.as_ref(), args.search(q))
        .usage_context("--joint")
}
