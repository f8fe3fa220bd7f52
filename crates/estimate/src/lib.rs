//! One estimate request: what estimates each record (a trained estimator,
//! a classic method, the multi-start output-error fit, or given values),
//! the model its records come from, found once, and what to do with the
//! estimates (check them against their records, refine them, fit one
//! estimate of every record, estimate windows of each record). The
//! command line's `estimate` and the Python package build an
//! [`EstimateRequest`] and only print or convert the typed rows it gives.

use twostage_baselines::MethodSettings;
use twostage_estimator::{Estimator, SignalNames};
use twostage_models::{FixedValues, IoData, ModelSpec, Simulator};
use twostage_refine::{CheckPlan, RefineReason, SearchStarts};
use twostage_sources::{ClassicMethod, NamedModel};

mod choices;
mod draws;
mod failure;
mod joint;
mod methods;
mod model_of;
mod own;
mod records;
mod refiner;
mod request_error;
mod rows;
mod run;
mod sharpen;
mod table;
mod through_model;

pub use choices::{
    CheckSettings, GivenValues, RefineChoiceError, RefineWhich, Windows, values_outside_prior,
};
pub use draws::{PosteriorDraws, draws_refused};
pub use failure::{GivenValuesError, MethodFailure, RecordFailure};
pub use joint::{JointFitter, JointOfRecords, RecordOfJoint};
pub use methods::OUTPUT_ERROR_METHOD;
pub use model_of::{EstimatorModel, SharedSimulator};
pub use own::{OwnFit, fit_own_parameters};
pub use refiner::{
    EstimateRefiner, ModelFailure, RECORDS_TOGETHER, RefinedBy, RefinedEstimate, SearchOptima,
    ToRefine,
};
pub use request_error::{Purpose, RequestError, RequestProblem};
pub use rows::{
    AutoRefined, Estimates, Plant, RecordEstimate, RecordOutcome, RefineOutcome, Refined,
};
pub use run::{JointRun, RecordBatch, RecordPlace};
pub use sharpen::sharpen_refused;

use methods::Method;

/// What estimates each record.
pub enum EstimateWith {
    /// A trained two-stage estimator (its model is the one it was trained
    /// on; a model file of it is the request's `model`).
    Estimator(Box<Estimator>),
    /// A classic method of a built-in model (the request's `model`).
    Classic {
        /// The method.
        method: ClassicMethod,
        /// Its settings; the request's `seed` seeds it.
        settings: MethodSettings,
    },
    /// The multi-start output-error fit of any model that runs without
    /// noise on a given input: `starts` draws from the prior, each
    /// descended by Levenberg-Marquardt, seeded by the request's `seed`.
    OutputError {
        /// Random starts.
        starts: usize,
    },
    /// Given values, checked against their records (a published value,
    /// another tool's estimate).
    Given(GivenValues),
    /// The values of a parameter-value file
    /// ([`twostage_sources::parameter_values`]), read with the model's
    /// parameter names once the model is found, checked against their
    /// records; rows without values are left out and said in
    /// [`Estimating::notes`].
    GivenFile(std::path::PathBuf),
    /// Given values of the model an estimator was trained on (its
    /// built-in model, or the request's model file of it), checked
    /// against their records: the estimator is not run.
    GivenOfEstimator {
        /// The values.
        values: GivenValues,
        /// The estimator whose model runs them.
        estimator: Box<Estimator>,
    },
}

/// Everything an estimate of records needs: see the module's doc. Built
/// by its setters from [`EstimateRequest::new`], then
/// [`prepared`](EstimateRequest::prepare).
///
/// ```
/// use twostage::{CheckSettings, EstimateRequest, EstimateWith, RefinePolicy, RefineWhich};
/// let request = EstimateRequest::new(EstimateWith::OutputError { starts: 3 })
///     .check_settings(CheckSettings { runs: 19, score_from: 10, score_to: None })
///     .seed(4);
/// assert!(!request.checks(), "settings alone ask for no check");
/// let request = request.refine(Some(RefineWhich::Auto(RefinePolicy::default())));
/// assert!(request.checks(), "refine = auto checks to choose");
/// ```
pub struct EstimateRequest {
    with: EstimateWith,
    model: Option<NamedModel>,
    check: bool,
    check_settings: CheckSettings,
    refine: Option<RefineWhich>,
    joint: bool,
    windows: Option<Windows>,
    seed: u64,
    prior_starts: Option<usize>,
    allow_outside_prior: bool,
    samples: Option<usize>,
    sharpen: Option<usize>,
    region_at: Option<RegionValues>,
    fix: FixedValues,
}

/// Parameter values to test against each record's posterior region
/// ([`EstimateRequest::region_at`]).
#[derive(Debug, Clone)]
pub enum RegionValues {
    /// Values given in code: one row for every record, or a row per
    /// experiment.
    Given(GivenValues),
    /// A parameter-value file ([`twostage_sources::parameter_values`]),
    /// read with the estimator's parameter names.
    File(std::path::PathBuf),
}

impl EstimateRequest {
    /// A request that estimates with `with` and nothing else.
    pub fn new(with: EstimateWith) -> Self {
        Self {
            with,
            model: None,
            check: false,
            check_settings: CheckSettings::default(),
            refine: None,
            joint: false,
            windows: None,
            seed: 0,
            prior_starts: None,
            allow_outside_prior: false,
            samples: None,
            sharpen: None,
            region_at: None,
            fix: FixedValues::default(),
        }
    }

    /// Hold the trained estimator's parameters of `values` there
    /// ([`Estimator::holding`]): its rows are of the other parameters, and
    /// its check, refinement and joint fit search them alone, the model
    /// holding the values, as an estimator trained with them held does.
    ///
    /// ```
    /// use twostage::models::{FixedValues, PacejkaCar, Simulator, experiment_rng};
    /// use twostage::{EstimateRequest, EstimateWith, Silent, TwoStage};
    /// let car = PacejkaCar::builder().n_samples(100).build()?;
    /// let estimator = TwoStage::builder(&car)
    ///     .simulations(200).validation(0).calibration(50).seed(1).linear(1e-6)?.train()?;
    /// let estimating = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator)))
    ///     .fix(FixedValues::parse(&["pK1=-30"])?)
    ///     .prepare()?;
    /// assert_eq!(estimating.param_names(), ["pK2"]);
    /// // Only a trained estimator holds values.
    /// let refused = EstimateRequest::new(EstimateWith::OutputError { starts: 4 })
    ///     .model(Some(twostage::sources::NamedModel::builtin("pacejka")?))
    ///     .fix(FixedValues::parse(&["pK1=-30"])?)
    ///     .prepare()
    ///     .err()
    ///     .expect("refused");
    /// assert!(refused.to_string().contains("give a trained estimator"), "{refused}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn fix(mut self, values: FixedValues) -> Self {
        self.fix = values;
        self
    }

    /// The model the records come from: a built-in one or a model file.
    /// An estimator knows its own (a model file of it is needed to check,
    /// refine or jointly fit an estimator of a model file); a classic
    /// method, the output-error fit and given values need it.
    pub fn model(mut self, model: Option<NamedModel>) -> Self {
        self.model = model;
        self
    }

    /// Check each estimate against its record (with
    /// [`Self::check_settings`]).
    pub fn check_records(mut self, asked: bool) -> Self {
        self.check = asked;
        self
    }

    /// How a check ranks a record, whether it is asked for or implied by
    /// `refine = auto` (default [`CheckSettings::default`]).
    pub fn check_settings(mut self, settings: CheckSettings) -> Self {
        self.check_settings = settings;
        self
    }

    /// Refine an estimator's estimates through the model.
    pub fn refine(mut self, which: Option<RefineWhich>) -> Self {
        self.refine = which;
        self
    }

    /// One estimate of the plant behind every record, after theirs
    /// ([`Estimating::joint`]).
    pub fn joint(mut self, joint: bool) -> Self {
        self.joint = joint;
        self
    }

    /// Also draw `samples` parameter vectors from the estimator's
    /// posterior given each record (seeded by the request's seed and the
    /// record's place: [`RecordEstimate::posterior`]).
    pub fn samples(mut self, samples: Option<usize>) -> Self {
        self.samples = samples;
        self
    }

    /// With draws: sharpen them through the estimator's model with
    /// `simulations` runs of it per record, in three rounds: each round runs
    /// the model, with its noise, on the record's input near the record's
    /// posterior (first the estimator's, then the round before's), fits
    /// stage 1's features of the runs as a Gaussian whose mean is linear in
    /// the unbounded parameters, and draws its likelihood of the record's
    /// features times the prior exactly. For a posterior narrower than the
    /// estimator resolves from its chart; the draws are then of the
    /// features' local likelihood, not the network's.
    pub fn sharpen(mut self, simulations: Option<usize>) -> Self {
        self.sharpen = simulations;
        self
    }

    /// With draws: test `values` against each record's posterior, the
    /// smallest level of its region of highest density that holds them
    /// ([`PosteriorDraws::region_level`]): whether a published value, a
    /// design value or another tool's estimate is one the record allows.
    pub fn region_at(mut self, values: Option<RegionValues>) -> Self {
        self.region_at = values;
        self
    }

    /// Estimate windows of each record.
    pub fn windows(mut self, windows: Option<Windows>) -> Self {
        self.windows = windows;
        self
    }

    /// Seeds the random methods, the check's own records and the best-fit
    /// search's starts over the prior (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The best-fit search's starts over the prior besides the estimate
    /// and its interval's corners (default
    /// [`SearchStarts::default_from_prior`]).
    pub fn prior_starts(mut self, starts: Option<usize>) -> Self {
        self.prior_starts = starts;
        self
    }

    /// Accept given values outside the model's prior box (refused by
    /// default: a model may not even run there, and its estimators never
    /// saw it).
    pub fn allow_outside_prior(mut self, allowed: bool) -> Self {
        self.allow_outside_prior = allowed;
        self
    }

    /// Whether the records are checked: asked, or to choose which to
    /// refine ([`RefineWhich::checks`]).
    pub fn checks(&self) -> bool {
        self.check || self.refine.is_some_and(RefineWhich::checks)
    }

    /// The request ready to estimate records: the model found and loaded
    /// once for every use (check, refinement, joint fit), the method
    /// built.
    ///
    /// ```
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::{CheckSettings, EstimateRequest, EstimateWith, Silent, TwoStage};
    /// let model = Benchmark::new();
    /// let estimator = TwoStage::builder(&model)
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(400).validation(0).calibration(200).seed(3).train()?;
    /// let mut record = model.spec().new_record();
    /// model.simulate(&[0.3], &mut experiment_rng(8, 0), &mut record)?;
    /// let request = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
    ///     .check_records(true)
    ///     .check_settings(CheckSettings { runs: 39, score_from: 0, score_to: None });
    /// let estimating = request.prepare()?;
    /// let estimates = estimating.estimate("records", vec![("7".into(), Ok(record.clone()))], &Silent);
    /// let (_, row) = estimates.rows[0].1.as_ref().map_err(ToString::to_string)?;
    /// assert_eq!(row.theta, estimator.estimate(record.input(0), record.output(0))?);
    /// let check = row.check.as_ref().expect("checked").as_ref().map_err(Clone::clone)?;
    /// assert!(check.explained());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`RequestError`]: what it was for (the method, the check, the
    /// refinement, the joint fit) and what went wrong (a model file of
    /// another model, a model that cannot run without noise, a method the
    /// model lacks, no model where one is needed).
    pub fn prepare(mut self) -> Result<Estimating, RequestError> {
        if !self.fix.is_empty() {
            let EstimateWith::Estimator(estimator) = &mut self.with else {
                return Err(RequestError {
                    purpose: Purpose::Fix,
                    error: RequestProblem::HeldNeedsEstimator,
                });
            };
            **estimator = estimator
                .holding(&self.fix)
                .map_err(|e| RequestError::new(Purpose::Fix, e.into()))?;
        }
        if self.model.is_some()
            && matches!(self.with, EstimateWith::Estimator(_))
            && !(self.checks() || self.refine.is_some() || self.joint || self.sharpen.is_some())
        {
            return Err(RequestError {
                purpose: Purpose::Model,
                error: RequestProblem::ModelNotRead,
            });
        }
        if let Some(refused) = self.windows.and_then(Windows::refused) {
            return Err(RequestError {
                purpose: Purpose::Windows,
                error: refused,
            });
        }
        if let Some(samples) = self.samples {
            let estimator = match &self.with {
                EstimateWith::Estimator(estimator) => Some(estimator.as_ref()),
                _ => None,
            };
            let refined = self.refine.is_some() || self.joint;
            if let Some(refused) = draws::draws_refused(samples, estimator, refined) {
                return Err(RequestError {
                    purpose: Purpose::Samples,
                    error: refused,
                });
            }
        }
        if let Some(refused) =
            sharpen::sharpen_refused(self.sharpen, self.samples, self.region_at.is_some())
        {
            return Err(RequestError {
                purpose: Purpose::Samples,
                error: refused,
            });
        }
        let region = match (self.region_at.take(), &self.with) {
            (None, _) => None,
            (Some(_), _) if self.samples.is_none() => {
                return Err(RequestError {
                    purpose: Purpose::Region,
                    error: RequestProblem::Samples(
                        "values are tested against the posterior's draws: ask for draws too".into(),
                    ),
                });
            }
            (Some(values), EstimateWith::Estimator(estimator)) => {
                Some(draws::region_values(values, estimator.param_names())?)
            }
            // Draws of anything but an estimator were refused above.
            (Some(_), _) => None,
        };
        let settings = Settings {
            checks: self.checks(),
            check: self.check_settings,
            refine: self.refine,
            joint: self.joint,
            windows: self.windows,
            seed: self.seed,
            prior_starts: self.prior_starts,
            allow_outside_prior: self.allow_outside_prior,
            samples: self.samples,
            sharpen: self.sharpen,
        };
        // The estimator's model, found once where a use asks for it; the
        // first use names a lookup that fails.
        let of_estimator = match &self.with {
            EstimateWith::Estimator(estimator) => {
                settings.model_use().map(|purpose| (estimator, purpose))
            }
            EstimateWith::GivenOfEstimator { estimator, .. } => Some((estimator, Purpose::Given)),
            _ => None,
        };
        let model = of_estimator
            .map(|(estimator, purpose)| {
                EstimatorModel::find(estimator, self.model.as_ref())
                    .map_err(|e| RequestError::new(purpose, e.into()))
            })
            .transpose()?;
        match self.with {
            EstimateWith::Estimator(estimator) => settings
                .two_stage(estimator, model.as_ref())
                .map(|mut estimating| {
                    if let Some((values, skipped)) = region {
                        estimating.region = Some(values);
                        estimating.notes.extend(skipped);
                    }
                    estimating
                }),
            EstimateWith::GivenOfEstimator { values, .. } => settings.through_model(
                EstimateWith::Given(values),
                model.as_ref().map(EstimatorModel::named),
            ),
            other => settings.through_model(other, self.model.as_ref()),
        }
    }
}

/// The settings of a request that its preparation reads.
#[derive(Clone, Copy)]
struct Settings {
    checks: bool,
    check: CheckSettings,
    refine: Option<RefineWhich>,
    joint: bool,
    windows: Option<Windows>,
    seed: u64,
    prior_starts: Option<usize>,
    allow_outside_prior: bool,
    samples: Option<usize>,
    sharpen: Option<usize>,
}

impl Settings {
    /// The best-fit search of a model of `q` parameters.
    fn search(self, q: usize) -> SearchStarts {
        SearchStarts {
            from_prior: self
                .prior_starts
                .unwrap_or_else(|| SearchStarts::default_from_prior(q)),
            seed: self.seed,
        }
    }

    /// The check's plan for a model of `q` parameters.
    fn plan(self, q: usize) -> CheckPlan {
        CheckPlan {
            noisy: self.check.runs,
            seed: self.seed,
            score_from: self.check.score_from,
            score_to: self.check.score_to,
            prior_starts: self.search(q).from_prior,
        }
    }

    /// The first use of a trained estimator's model, which names a
    /// lookup that fails: the check, the refinement, the joint fit, or
    /// none (the model is not needed).
    fn model_use(self) -> Option<Purpose> {
        if self.checks {
            Some(Purpose::Check)
        } else if self.refine.is_some() {
            Some(Purpose::Refine)
        } else if self.joint {
            Some(Purpose::Joint)
        } else if self.sharpen.is_some() {
            Some(Purpose::Samples)
        } else {
            None
        }
    }

    /// A trained estimator's request: its `model`, found where a use asks
    /// for it ([`Self::model_use`]), for each use.
    fn two_stage(
        self,
        estimator: Box<Estimator>,
        model: Option<&EstimatorModel<'_>>,
    ) -> Result<Estimating, RequestError> {
        let q = estimator.param_names().len();
        let checker = match (model, self.checks) {
            (Some(model), true) => Some(
                model
                    .simulator()
                    .map_err(|e| RequestError::new(Purpose::Check, e.into()))?,
            ),
            _ => None,
        };
        let refiner = match (model, self.refine) {
            (Some(model), Some(_)) => Some(
                EstimateRefiner::new(&estimator, model)
                    .map_err(|e| RequestError::new(Purpose::Refine, e.into()))?
                    .search(self.search(q)),
            ),
            _ => None,
        };
        let joint = match (model, self.joint) {
            (Some(model), true) => Some(
                JointFitter::new(&estimator, model, self.search(q))
                    .map_err(|e| RequestError::new(Purpose::Joint, e.into()))?,
            ),
            _ => None,
        };
        let sharpener = match (model, self.sharpen) {
            (Some(model), Some(_)) => Some(
                model
                    .simulator()
                    .map_err(|e| RequestError::new(Purpose::Samples, e.into()))?,
            ),
            _ => None,
        };
        let shape = estimator.record_shape();
        Ok(Estimating {
            names: estimator.param_names().to_vec(),
            signals: estimator.signal_names(),
            sample_time: shape.sample_time,
            trained: Some(shape.n_samples),
            prior_box: Some((estimator.lower().to_vec(), estimator.upper().to_vec())),
            checker,
            refiner,
            joint,
            refine: self.refine,
            windows: self.windows,
            plan: self.plan(q),
            samples: self.samples,
            sharpen: self.sharpen,
            sharpener,
            region: None,
            // The joint fit, as a refinement, fits records of any length.
            method: Method::two_stage(estimator, self.refine.is_some() || self.joint),
            notes: Vec::new(),
        })
    }

    /// Given values as the method, unless some lie outside the prior
    /// without leave.
    fn given(
        self,
        values: GivenValues,
        spec: &ModelSpec,
        purpose: Purpose,
    ) -> Result<Method, RequestError> {
        if !self.allow_outside_prior
            && let Some(outside) = values.outside_prior(spec)
        {
            return Err(RequestError {
                purpose,
                error: outside,
            });
        }
        Ok(Method::Given(values))
    }

    /// A classic method's, the output-error fit's or given values'
    /// request: each needs the model `given`.
    fn through_model(
        self,
        with: EstimateWith,
        given: Option<&NamedModel>,
    ) -> Result<Estimating, RequestError> {
        let purpose = match &with {
            EstimateWith::Classic { .. } => Purpose::Method,
            EstimateWith::OutputError { .. } => Purpose::OutputError,
            EstimateWith::Given(_)
            | EstimateWith::GivenFile(_)
            | EstimateWith::GivenOfEstimator { .. }
            | EstimateWith::Estimator(_) => Purpose::Given,
        };
        let without = |purpose| RequestError {
            purpose,
            error: RequestProblem::NeedsEstimator,
        };
        if self.refine.is_some() {
            return Err(without(Purpose::Refine));
        }
        if self.joint {
            return Err(without(Purpose::Joint));
        }
        let named = given.ok_or(RequestError {
            purpose,
            error: RequestProblem::NoModel,
        })?;
        // Built once: the method's and the check's.
        let simulator: SharedSimulator = named
            .simulator()
            .map_err(|e| RequestError::new(purpose, e.into()))?
            .into();
        let mut notes = Vec::new();
        let (method, spec) = match with {
            EstimateWith::Classic { method, settings } => {
                let builtin = named.as_builtin().ok_or_else(|| RequestError {
                    purpose,
                    error: RequestProblem::NotBuiltIn {
                        method: method.name(),
                        model: named.name().to_string(),
                    },
                })?;
                let settings = MethodSettings {
                    seed: self.seed,
                    ..settings
                };
                let classic = twostage_baselines::classic_estimator(builtin, method, &settings)
                    .map_err(|e| RequestError::new(purpose, Box::new(e)))?;
                (Method::Classic(classic), simulator.spec().clone())
            }
            EstimateWith::OutputError { starts } => {
                let spec = simulator.spec().clone();
                let method = Method::output_error(simulator.clone(), starts, self.seed)
                    .map_err(|e| RequestError::new(purpose, e.into()))?;
                (method, spec)
            }
            EstimateWith::GivenFile(path) => {
                let spec = simulator.spec().clone();
                let refused = |why| RequestError {
                    purpose,
                    error: RequestProblem::Values(why),
                };
                let read = twostage_sources::parameter_values::read(&path, spec.param_names())
                    .map_err(refused)?;
                notes = read.skipped;
                let values = GivenValues::new(read.rows, &path.display().to_string())
                    .map_err(|e| refused(e.to_string()))?;
                (self.given(values, &spec, purpose)?, spec)
            }
            EstimateWith::Given(values) => {
                let spec = simulator.spec().clone();
                (self.given(values, &spec, purpose)?, spec)
            }
            EstimateWith::Estimator(_) | EstimateWith::GivenOfEstimator { .. } => {
                unreachable!("prepare resolves an estimator and its model first")
            }
        };
        let checker = self.checks.then_some(simulator);
        Ok(Estimating {
            names: spec.param_names().to_vec(),
            signals: SignalNames {
                inputs: spec.input_names().to_vec(),
                outputs: spec.output_names().to_vec(),
            },
            sample_time: spec.sample_time(),
            trained: None,
            prior_box: None,
            checker,
            refiner: None,
            joint: None,
            refine: self.refine,
            windows: self.windows,
            plan: self.plan(spec.param_names().len()),
            method,
            samples: None,
            sharpen: None,
            sharpener: None,
            region: None,
            notes,
        })
    }
}

/// A prepared [`EstimateRequest`]: estimates records, file by file or
/// batch by batch, and the joint estimate of them all.
pub struct Estimating {
    method: Method,
    names: Vec<String>,
    signals: SignalNames,
    sample_time: f64,
    trained: Option<usize>,
    prior_box: Option<(Vec<f64>, Vec<f64>)>,
    checker: Option<SharedSimulator>,
    refiner: Option<EstimateRefiner>,
    joint: Option<JointFitter>,
    refine: Option<RefineWhich>,
    windows: Option<Windows>,
    plan: CheckPlan,
    samples: Option<usize>,
    /// Runs of the model that sharpen each record's draws.
    sharpen: Option<usize>,
    /// The model the draws are sharpened through.
    sharpener: Option<SharedSimulator>,
    /// Values tested against each record's posterior region.
    region: Option<GivenValues>,
    notes: Vec<String>,
}

impl Estimating {
    /// What the preparation left out and a door should say (rows of a
    /// values file without values), one line each.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The parameters estimated, in the rows' order.
    pub fn param_names(&self) -> &[String] {
        &self.names
    }

    /// The signals a record holds (the record files' columns).
    pub fn signals(&self) -> &SignalNames {
        &self.signals
    }

    /// How the records are laid out in a file: their signals' columns and
    /// the sample time a `time` column steps by.
    pub fn record_format(&self) -> twostage_sources::record_file::RecordFormat {
        twostage_sources::record_file::RecordFormat {
            inputs: self.signals.inputs.clone(),
            outputs: self.signals.outputs.clone(),
            sample_time: self.sample_time,
        }
    }

    /// The records' sample time.
    pub fn sample_time(&self) -> f64 {
        self.sample_time
    }

    /// The record length an estimator was trained and validated on
    /// (`None` for the other ways of estimating).
    pub fn trained_length(&self) -> Option<usize> {
        self.trained
    }

    /// The prior's box (lower, upper), which an estimator's intervals
    /// stay inside.
    pub fn prior_box(&self) -> Option<(&[f64], &[f64])> {
        self.prior_box
            .as_ref()
            .map(|(lo, hi)| (lo.as_slice(), hi.as_slice()))
    }

    /// Whether the request asked for the joint estimate.
    pub fn joins(&self) -> bool {
        self.joint.is_some()
    }

    /// The model a check simulates: the one the refinement and the joint
    /// fit share, where they run one.
    fn check_model(&self) -> Option<&dyn Simulator> {
        self.checker.as_deref()
    }

    /// Why `RefineWhich::Auto` refines a record (`None`: it keeps its
    /// estimate).
    fn reason(&self, record: &IoData, e: &RecordEstimate) -> Option<RefineReason> {
        let Some(RefineWhich::Auto(policy)) = self.refine else {
            return None;
        };
        let other_length = self.trained.is_some_and(|n| n != record.n_samples());
        match &e.check {
            Some(Ok(c)) => policy.reason(c, e.out_of_distribution(), other_length),
            _ => other_length.then_some(RefineReason::OtherLength),
        }
    }
}

#[cfg(test)]
mod tests;
