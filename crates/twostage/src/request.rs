//! One training request: every setting of a training run, as plain data
//! with its defaults once, and the one function that trains it. The
//! command line, the Python package and the shard commands build a
//! [`TrainingRequest`] and hand it here, so the same request gives the
//! same estimator file byte for byte whichever door it came through.

use serde::{Deserialize, Serialize};
use twostage_models::{FixedValues, Simulator, WithFixed};

use twostage_auto::{AutoDesign, AutoOutcome, Budget};
use twostage_compress::CompressorConfig;
use twostage_estimator::Estimator;
use twostage_fit::{MixtureDensity, RegressorConfig};
use twostage_sources::NamedModel;
use twostage_sources::Progress;
use twostage_sources::RecordSource;
use twostage_sources::{ChartDir, ChartGiven, DEFAULT_PRESET_SIMULATIONS, Preset, RecordsRequest};
use twostage_sources::{ShardPlan, ShardedChart};
use twostage_train::{Error, Result};
use twostage_train::{RunSettings, TwoStage};

/// Every setting of one training run. `Default` is the command line's
/// `twostage train` with no option: the model's default preset,
/// simulated records and [`RunSettings::default`].
///
/// ```
/// use twostage::{NamedModel, RunSettings, Silent, TrainingRequest};
/// let request = TrainingRequest {
///     simulations: Some(200),
///     compress: Some("arx:2,2".into()),
///     settings: RunSettings { validation: 100, calibration: 100, ..RunSettings::default() },
///     ..TrainingRequest::default()
/// };
/// // Plain data: what the Python package and a JSON file hold too.
/// let json = serde_json::to_string(&request)?;
/// assert_eq!(serde_json::from_str::<TrainingRequest>(&json)?, request);
/// let trained = request.train(&NamedModel::builtin("benchmark")?, &Silent)?;
/// assert_eq!(trained.estimator().training().simulations, 200);
/// assert_eq!(trained.estimator().training().seed, 1);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainingRequest {
    /// A preset of the model's, by name (`None`: its default: a built-in
    /// model's `paper`, a model file's first).
    pub preset: Option<String>,
    /// Training simulations m (default: the preset's).
    pub simulations: Option<usize>,
    /// Stage 1 as `arx:NA,NB` and friends (default: the preset's).
    pub compress: Option<String>,
    /// Stage 2 as `mlp:H` and friends (default: the preset's).
    pub fit: Option<String>,
    /// Search compressors and networks within this budget instead of
    /// training a preset.
    pub search: Option<Budget>,
    /// Also fit a conditional density of the parameters of this many
    /// Gaussian components (the posterior the estimator then draws
    /// from; [`MixtureDensity::with_components`]); with a search, the
    /// most components, the count chosen by held-out likelihood
    /// ([`MixtureDensity::choosing_components`]).
    pub posterior: Option<usize>,
    /// Seed, sizes, levels.
    pub settings: RunSettings,
    /// Where the records come from.
    pub records: RecordsRequest,
    /// The model's parameters held at values (`--fix NAME=VALUE`): the
    /// estimator estimates the others, and records that its model holds
    /// them. Simulated records only: a chart's were simulated at their
    /// own values.
    pub fix: FixedValues,
}

/// What a request trained: an estimator, and the candidates of a search.
#[derive(Debug)]
#[expect(
    clippy::large_enum_variant,
    reason = "made once per training run and read at once: a box would only add an indirection"
)]
pub enum Trained {
    /// A preset (or the structure the request named), trained.
    Designed(Estimator),
    /// The winner of an automatic design, with every candidate.
    Searched(AutoOutcome),
}

impl Trained {
    /// The estimator.
    pub fn estimator(&self) -> &Estimator {
        match self {
            Self::Designed(estimator) => estimator,
            Self::Searched(outcome) => &outcome.estimator,
        }
    }

    /// The estimator, owned.
    pub fn into_estimator(self) -> Estimator {
        match self {
            Self::Designed(estimator) => estimator,
            Self::Searched(outcome) => outcome.estimator,
        }
    }

    /// The same, its estimator of a model whose parameters `fixed` were
    /// held at values ([`Estimator::with_fixed`]).
    pub fn with_fixed(self, fixed: FixedValues) -> Self {
        match self {
            Self::Designed(estimator) => Self::Designed(estimator.with_fixed(fixed)),
            Self::Searched(mut outcome) => {
                outcome.estimator = outcome.estimator.with_fixed(fixed);
                Self::Searched(outcome)
            }
        }
    }

    /// The search's report, when the design was searched.
    pub fn search(&self) -> Option<&AutoOutcome> {
        match self {
            Self::Designed(_) => None,
            Self::Searched(outcome) => Some(outcome),
        }
    }
}

/// The share of a time budget the posterior's density is fitted in,
/// where the automatic design searches and a posterior is asked: the
/// search takes the rest.
pub const POSTERIOR_SHARE: f64 = 1.0 / 3.0;

impl TrainingRequest {
    /// The steps the run takes, for a line such as "training the benchmark
    /// estimator (simulate, compress, fit, calibrate, validate)";
    /// `searching` as [`Self::search_budget`] says.
    pub fn steps(&self, searching: bool) -> String {
        let read = match &self.records {
            RecordsRequest::Simulated => "simulate",
            RecordsRequest::Chart { .. } | RecordsRequest::Given { .. } => "read the chart",
            RecordsRequest::Shards { .. } => "merge the shards",
        };
        let build = if searching {
            "search transforms, compressors and networks"
        } else {
            "compress, fit"
        };
        format!("{read}, {build}, calibrate, validate")
    }

    /// The preset the request trains on `model`: the named (or default)
    /// one with the request's structure and size put in. A model without
    /// presets takes both stages from the request, and
    /// [`DEFAULT_PRESET_SIMULATIONS`] unless the request gives m.
    ///
    /// # Errors
    /// An unknown preset, a model without presets and a request that does
    /// not give both stages, or a structure that does not parse.
    pub fn preset(&self, model: &NamedModel) -> Result<Preset> {
        let mut preset = match (&self.compress, &self.fit) {
            (Some(compress), Some(fit))
                if self.preset.is_none() && model.preset_names().is_empty() =>
            {
                Preset {
                    compressor: compress.parse::<CompressorConfig>()?,
                    regressor: fit.parse::<RegressorConfig>()?,
                    simulations: DEFAULT_PRESET_SIMULATIONS,
                }
            }
            _ => model.preset(self.preset.as_deref())?,
        };
        if let Some(m) = self.simulations {
            preset.simulations = m;
        }
        if let Some(spec) = &self.compress {
            preset.compressor = spec.parse::<CompressorConfig>()?;
        }
        if let Some(spec) = &self.fit {
            preset.regressor = spec.parse::<RegressorConfig>()?;
        }
        Ok(preset)
    }

    /// The search this request runs: the one it asks for, or, when it
    /// names no design and the model has no preset, the automatic design
    /// at the default budget, or on the request's simulations when it
    /// gives only those (`None`: train the preset).
    ///
    /// # Errors
    /// A search asked for together with a design (preset, size, stages).
    pub fn search_budget(&self, model: &NamedModel) -> Result<Option<Budget>> {
        let design_given = [
            ("preset", self.preset.is_some()),
            ("simulations", self.simulations.is_some()),
            ("compress", self.compress.is_some()),
            ("fit", self.fit.is_some()),
        ];
        let named = design_given.iter().find(|(_, given)| *given);
        match (self.search, named) {
            (Some(budget), Some((name, _))) => Err(Error::setting(
                "search",
                format!("{budget:?} with a {name}"),
                "the automatic design chooses the structure and the chart size itself: \
                         leave out the preset, simulations, compress and fit",
            )),
            (Some(budget), None) => Ok(Some(budget)),
            // No preset to train: search, on the simulations asked for
            // (every candidate) or within the default time.
            (None, _)
                if model.preset_names().is_empty()
                    && self.preset.is_none()
                    && self.compress.is_none()
                    && self.fit.is_none() =>
            {
                Ok(Some(
                    self.simulations
                        .map_or_else(Budget::default, Budget::Simulations),
                ))
            }
            (None, _) => Ok(None),
        }
    }

    /// The chart of this request's run as shards hold it: the model, the
    /// seed, the training (the request's or the preset's m), calibration
    /// and validation sizes, and the compressor of compressed shards.
    ///
    /// ```
    /// use twostage::{ModelFile, NamedModel, RunSettings, TrainingRequest};
    /// // A model file without presets: the size is the request's.
    /// let file = ModelFile::parse(
    ///     "[model]\nname = \"sir\"\n[[parameter]]\nname = \"beta\"\n\
    ///      prior = { dist = \"uniform\", low = 0.1, high = 1.0 }\n\
    ///      [signals]\ninputs = []\noutputs = [\"I\"]\nsamples = 10\n",
    ///     "sir.toml",
    /// )?;
    /// let request = TrainingRequest {
    ///     simulations: Some(800),
    ///     settings: RunSettings { validation: 100, ..RunSettings::default() },
    ///     ..TrainingRequest::default()
    /// };
    /// let plan = request.shard_plan(&NamedModel::File(Box::new(file)))?;
    /// assert_eq!(plan.counts, twostage::sources::RoleCounts::new(800, 4000, 100));
    /// assert_eq!(plan.seed, 1);
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// No size given and an unknown preset (or a model without presets).
    pub fn shard_plan(&self, model: &NamedModel) -> Result<ShardPlan> {
        // A model without presets shards as well when the size is given:
        // shards hold records, not a structure.
        let simulations = match self.simulations {
            Some(m) => m,
            None => self.preset(model)?.simulations,
        };
        Ok(ShardPlan {
            model: model.name().to_string(),
            model_fingerprint: model.fingerprint(),
            seed: self.settings.seed_or_default(),
            counts: twostage_sources::RoleCounts::new(
                simulations,
                self.settings.calibration,
                self.settings.validation,
            ),
            compressor: self.compress.clone(),
        })
    }

    /// Train the request on `model`, with the model's own simulator (or,
    /// for records read from files, the model without one).
    ///
    /// # Errors
    /// As [`Self::train_with`], and what starting the model's source
    /// reports.
    pub fn train(&self, model: &NamedModel, progress: &dyn Progress) -> Result<Trained> {
        let simulator = match self.records {
            RecordsRequest::Simulated => model.simulator()?,
            _ => model.chart_model()?,
        };
        self.train_with(model, simulator.as_ref(), progress)
    }

    /// Train the request on `model` with `simulator` (which simulates the
    /// model `model` describes, e.g. a Python function behind a model file
    /// without a source): the preset, or the automatic design
    /// ([`Self::search_budget`]), on the request's records, whatever their
    /// source.
    ///
    /// # Errors
    /// A search asked for with a design; an unknown preset or a structure
    /// that does not parse; shards of another model description; what
    /// [`TwoStage::train`] or [`AutoDesign`] report.
    pub fn train_with(
        &self,
        model: &NamedModel,
        simulator: &dyn Simulator,
        progress: &dyn Progress,
    ) -> Result<Trained> {
        if self.fix.is_empty() {
            return self.train_on(model, simulator, progress);
        }
        if !matches!(self.records, RecordsRequest::Simulated) {
            return Err(Error::setting(
                "fix",
                self.fix.to_string(),
                "a chart's or shards' records were simulated at their own values of these \
                 parameters: hold them on simulated records, or simulate a chart without them",
            ));
        }
        let held = WithFixed::new(simulator, &self.fix).map_err(twostage_sources::Error::from)?;
        progress.note(&format!(
            "holding {} (not estimated): the estimator is of {}",
            self.fix,
            held.spec().param_names().join(", ")
        ));
        Ok(self
            .train_on(model, &held, progress)?
            .with_fixed(self.fix.clone()))
    }

    /// [`Self::train_with`] on `simulator` as it is.
    fn train_on(
        &self,
        model: &NamedModel,
        simulator: &dyn Simulator,
        progress: &dyn Progress,
    ) -> Result<Trained> {
        let started = std::time::Instant::now();
        let mut search = self.search_budget(model)?;
        // A time budget holds the posterior's density too: the search
        // takes its first part, the density what is left of the whole.
        let density_by = match (search, self.posterior) {
            (Some(Budget::Seconds(seconds)), Some(_)) => {
                search = Some(Budget::Seconds(seconds * (1.0 - POSTERIOR_SHARE)));
                Some(started + std::time::Duration::from_secs_f64(seconds))
            }
            _ => None,
        };
        if let (Some(budget), None) = (search, self.search) {
            progress.note(&format!(
                "{} has no preset: searching for a design (automatic design, {}); add the \
                 [[preset]] printed at the end to the model file to train it again without \
                 searching",
                model.name(),
                budget.describe()
            ));
        }
        let mut builder = TwoStage::builder(simulator)
            .settings(self.settings.clone())
            .progress(progress);
        if let Some(components) = self.posterior {
            let density = MixtureDensity::with_components(components).map_err(|_| {
                Error::setting(
                    "posterior",
                    components.to_string(),
                    "at least 1 Gaussian component",
                )
            })?;
            // The automatic design chooses the density's components too,
            // by held-out likelihood, the asked count the most.
            let density = match search {
                Some(_) => density.choosing_components(),
                None => density,
            };
            builder = builder.posterior(match density_by {
                Some(end) => {
                    progress.note(&format!(
                        "the posterior's density is fitted within the time budget: the search \
                         takes its first {:.0}%, the density the rest",
                        100.0 * (1.0 - POSTERIOR_SHARE)
                    ));
                    density.stopped_by(end)
                }
                None => density,
            });
        }
        let builder = match search {
            Some(_) => builder,
            None => builder.preset(self.preset(model)?),
        };
        let run = |builder: TwoStage<'_, dyn Simulator>| -> Result<Trained> {
            Ok(match search {
                Some(budget) => Trained::Searched(
                    AutoDesign::new(simulator)
                        .budget(budget)
                        .settings(|_| builder)
                        .run()?,
                ),
                None => Trained::Designed(builder.train()?),
            })
        };
        let from_charts = |builder: TwoStage<'_, dyn Simulator>,
                           training: &ChartGiven,
                           calibration: Option<&ChartGiven>,
                           validation: Option<&ChartGiven>| {
            let open = |chart: Option<&ChartGiven>| chart.map(|c| c.open(simulator)).transpose();
            run(builder.records(RecordSource::Files {
                training: &training.open(simulator)?,
                calibration: open(calibration)?.as_ref(),
                validation: open(validation)?.as_ref(),
            }))
        };
        match &self.records {
            RecordsRequest::Simulated => run(builder),
            RecordsRequest::Chart {
                training,
                calibration,
                validation,
            } => {
                let folder = |dir: &ChartDir| ChartGiven::Folder(dir.clone());
                from_charts(
                    builder,
                    &folder(training),
                    calibration.as_ref().map(folder).as_ref(),
                    validation.as_ref().map(folder).as_ref(),
                )
            }
            RecordsRequest::Given {
                training,
                calibration,
                validation,
            } => from_charts(builder, training, calibration.as_ref(), validation.as_ref()),
            RecordsRequest::Shards { pattern } => {
                let chart = ShardedChart::open(pattern)?;
                if chart.plan().model_fingerprint != model.fingerprint() {
                    return Err(twostage_sources::Error::Shards {
                        what: chart.pattern().to_string(),
                        message: format!(
                            "the shards were simulated from another model description than {} \
                             (another model file, or this one since edited): simulate them \
                             again, or train with the model they came from",
                            model.name()
                        ),
                    }
                    .into());
                }
                let plan = chart.plan();
                progress.note(&format!(
                    "merging {} shards: {} training, {} calibration and {} validation records, \
                     seed {}",
                    chart.files().len(),
                    plan.counts.training,
                    plan.counts.calibration,
                    plan.counts.validation,
                    plan.seed
                ));
                run(builder.records(RecordSource::Shards(&chart)))
            }
        }
    }
}
