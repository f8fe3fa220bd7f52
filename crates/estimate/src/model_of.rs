//! The model an estimator was trained on, found once for a run and its
//! simulator built once, shared by everything the run does through it.

use std::borrow::Cow;
use std::cell::OnceCell;
use std::sync::Arc;

use twostage_estimator::Estimator;
use twostage_models::{BuiltinModel, FixedValues, Simulator, WithFixed};
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
    /// The parameters the estimator's model held at values: its
    /// simulator holds them too.
    fixed: FixedValues,
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
            fixed: estimator.fixed().clone(),
            built: OnceCell::new(),
        })
    }

    /// The model found.
    pub fn named(&self) -> &NamedModel {
        &self.named
    }

    /// The built-in model whose exact likelihood refines the estimates:
    /// the estimator's built-in model where no model was given and no
    /// parameter is held (a model given, built-in or a file, and a model
    /// with parameters held, are refined through their simulators).
    pub fn exact_likelihood(&self) -> Option<BuiltinModel> {
        if self.given || !self.fixed.is_empty() {
            None
        } else {
            self.named.as_builtin()
        }
    }

    /// The model's simulator, with its noise and the estimator's held
    /// values: built at the first call, the same one (its processes
    /// started once) at every later call.
    ///
    /// # Errors
    /// A simulator that cannot be built (a model file's program that does
    /// not start, an FMU that does not load), or held values the model
    /// does not take (a model file since edited).
    pub fn simulator(&self) -> twostage_train::Result<SharedSimulator> {
        if let Some(built) = self.built.get() {
            return Ok(Arc::clone(built));
        }
        let whole = self.named.simulator()?;
        let built: SharedSimulator = if self.fixed.is_empty() {
            whole.into()
        } else {
            Arc::new(WithFixed::new(whole, &self.fixed).map_err(twostage_sources::Error::from)?)
        };
        Ok(Arc::clone(self.built.get_or_init(|| built)))
    }
}
