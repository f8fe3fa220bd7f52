//! The command line's side of refining and checking an estimator's
//! estimates: the model named on it (the refinement itself is
//! `twostage::EstimateRefiner`, shared with the Python package).

use anyhow::Result;
use twostage::EstimateRefiner;
use twostage::models::Simulator;
use twostage::{Estimator, NamedModel};

use super::EstimateArgs;
use crate::OrUsage;

/// The --model-file given, loaded: once for every use of it (check,
/// refinement, joint fit), so they read the same file.
pub(super) fn model_file(args: &EstimateArgs) -> Result<Option<NamedModel>> {
    args.model_file
        .as_ref()
        .map(|path| NamedModel::file(path).or_usage())
        .transpose()
}

/// The refinement of an estimator's estimates (see
/// [`EstimateRefiner::new`]) through `given`, the --model-file.
pub(super) fn refinement(
    estimator: &Estimator,
    given: Option<&NamedModel>,
    args: &EstimateArgs,
) -> Result<EstimateRefiner> {
    let q = estimator.param_names().len();
    Ok(EstimateRefiner::new(estimator, given)
        .usage_context("--refine")?
        .search(args.search(q)))
}

/// The model an estimator's records come from, to check them against:
/// `given` (the --model-file), else the estimator's built-in model.
pub(super) fn model_of(
    estimator: &Estimator,
    given: Option<&NamedModel>,
) -> Result<Box<dyn Simulator>> {
    NamedModel::trained_on(&estimator.training().model, given)
        .and_then(|model| model.simulator(false))
        .usage_context("--check simulates the model")
}

/// The joint fit of an estimator's records (see
/// [`twostage::JointFitter::new`]).
pub(super) fn joint_fitter(
    estimator: &Estimator,
    given: Option<&NamedModel>,
    args: &EstimateArgs,
) -> Result<twostage::JointFitter> {
    let q = estimator.param_names().len();
    twostage::JointFitter::new(estimator, given, args.search(q)).usage_context("--joint")
}
