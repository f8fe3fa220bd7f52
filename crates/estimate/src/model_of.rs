//! The model an estimator was trained on, found once for a run and its
//! simulator built once, shared by everything the run does through it.

use std::borrow::Cow;
use std::cell::OnceCell;
use std::sync::Arc;

use twostage_estimator::Estimator;
use twostage_models::{BuiltinModel, Simulator};
use twostage_sources::NamedModel;

/// One simulator of the model shared by everything an estimate request
/// runs through it (its check, its refinement, its joint fit): built once,
/// its processes started once.
pub type SharedSimulator = Arc<dyn Simulator>;

/// The model an estimator was trained on: the model given where it
/// describes that model, else the built-in model of that name. The one
/// place a run finds it; its simulator is built at the first use and
/// shared by every later one.
///
/// ```
/// use twostage::{EstimatorModel, TwoStage};
/// use twostage::models::Benchmark;
/// use twostage::sources::NamedModel;
/// let estimator = TwoStage::builder(&Benchmark::new())
///     .preset(twostage::paper_benchmark())
///     .simulations(300).validation(0).calibration(0).seed(3).train()?;
/// let model = EstimatorModel::find(&estimator, None)?;
/// assert_eq!(model.named().name(), "benchmark");
/// // Built once: both uses hold the same simulator.
/// let (a, b) = (model.simulator()?, model.simulator()?);
/// assert!(std::sync::Arc::ptr_eq(&a, &b));
/// // A model file of another model is refused, by name.
/// let other = NamedModel::builtin("pacejka")?;
/// let refused = EstimatorModel::find(&estimator, Some(&other)).err().unwrap();
/// assert!(refused.to_string().contains("trained on 'benchmark'"), "{refused}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct EstimatorModel<'a> {
    named: Cow<'a, NamedModel>,
    given: bool,
    built: OnceCell<SharedSimulator>,
}

impl<'a> EstimatorModel<'a> {
    /// The model `estimator` was trained on: `given` where it describes
    /// it, else the built-in model of its name. Nothing is built yet.
    ///
    /// # Errors
    /// `given` describes another model, or none is given and the
    /// estimator's model is not built in.
    pub fn find(
        estimator: &Estimator,
        given: Option<&'a NamedModel>,
    ) -> twostage_train::Result<Self> {
        Ok(Self {
            named: NamedModel::trained_on(&estimator.training().model, given)?,
            given: given.is_some(),
            built: OnceCell::new(),
        })
    }

    /// The model found.
    pub fn named(&self) -> &NamedModel {
        &self.named
    }

    /// The built-in model whose exact likelihood refines the estimates:
    /// the estimator's built-in model where no model was given (a model
    /// given, built-in or a file, is refined through its simulator).
    pub fn exact_likelihood(&self) -> Option<BuiltinModel> {
        if self.given {
            None
        } else {
            self.named.as_builtin()
        }
    }

    /// The model's simulator, with its noise: built at the first call,
    /// the same one (its processes started once) at every later call.
    ///
    /// # Errors
    /// A simulator that cannot be built (a model file's program that does
    /// not start, an FMU that does not load).
    pub fn simulator(&self) -> twostage_train::Result<SharedSimulator> {
        if let Some(built) = self.built.get() {
            return Ok(Arc::clone(built));
        }
        let built: SharedSimulator = self.named.simulator()?.into();
        Ok(Arc::clone(self.built.get_or_init(|| built)))
    }
}
