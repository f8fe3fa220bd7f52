//! The `TwoStage` builder: what a training run is asked for (the presets
//! are in the per-model table of the sources crate; the run's settings and
//! their defaults in `settings.rs`). [`TwoStage::prepare`] turns it into a
//! [`Run`], which trains it.

use crate::{Error, Result};
use twostage_estimator::Estimator;
use twostage_fit::Ridge;
use twostage_models::{Sampling, Simulator};

use crate::run::Run;
use crate::settings::RunSettings;
use twostage_compress::CompressorConfig;
use twostage_fit::{MixtureDensity, RegressorConfig};
use twostage_sources::paper_benchmark;
use twostage_sources::{Preset, Progress, RecordSource, Records, RunShape, Silent};

/// Builder of a two-stage estimator for one simulator.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `compressor` | ARX(5, 5) | any [`CompressorConfig`] |
/// | `regressor` | MLP with 10 tanh units, LM | any [`RegressorConfig`] |
/// | `posterior` | none | a [`MixtureDensity`] of the parameters given the features |
/// | `simulations` (m) | 1500 | >= 10 |
/// | `sampling` | the prior's own | [`Sampling`] of the training chart |
/// | `records` | simulated | a [`RecordSource`]: simulated, chart files or shards |
/// | `seed`, `calibration`, `alpha`, `validation`, `delta`, `max_failure_fraction` | [`RunSettings::default`] | as [`RunSettings`] says |
///
/// The compressor, regressor and m are the paper's benchmark preset
/// ([`paper_benchmark`]) until set.
///
/// ```
/// use twostage::{Estimator, TwoStage};
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
///
/// let model = Benchmark::builder().n_samples(300).build()?;
/// let estimator: Estimator = TwoStage::builder(&model)
///     .preset(twostage::paper_benchmark())
///     .simulations(300)
///     .validation(100)
///     .calibration(100)
///     .seed(1)
///     .train()?;
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.5], &mut experiment_rng(99, 0), &mut record)?;
/// let theta = estimator.estimate_record(&record)?;
/// assert!((-0.9..=0.9).contains(&theta[0]));
/// # Ok::<(), twostage::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct TwoStage<'a, S: ?Sized> {
    simulator: &'a S,
    compressor: CompressorConfig,
    regressor: RegressorConfig,
    posterior: Option<MixtureDensity>,
    simulations: usize,
    sampling: Option<Sampling>,
    settings: RunSettings,
    records: RecordSource<'a>,
    progress: &'a dyn Progress,
}

impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// Start a builder with the defaults of the table above.
    pub fn builder(simulator: &'a S) -> Self {
        let p = paper_benchmark();
        Self {
            simulator,
            compressor: p.compressor,
            regressor: p.regressor,
            posterior: None,
            simulations: p.simulations,
            sampling: None,
            settings: RunSettings::default(),
            records: RecordSource::Simulated,
            progress: &Silent,
        }
    }

    /// Take compressor, regressor and m from a preset.
    pub fn preset(mut self, preset: Preset) -> Self {
        self.compressor = preset.compressor;
        self.regressor = preset.regressor;
        self.simulations = preset.simulations;
        self
    }
    /// The stage-1 compressor.
    pub fn compressor(mut self, compressor: impl Into<CompressorConfig>) -> Self {
        self.compressor = compressor.into();
        self
    }
    /// The stage-2 method.
    pub fn regressor(mut self, regressor: RegressorConfig) -> Self {
        self.regressor = regressor;
        self
    }
    /// Also a conditional density of the parameters given stage 1's
    /// features, fitted on the training chart beside stage 2 (seeded by
    /// the run's seed): the estimator then draws from the posterior
    /// ([`Estimator::sample_record`]). None by default.
    pub fn posterior(mut self, density: MixtureDensity) -> Self {
        self.posterior = Some(density);
        self
    }

    /// A linear stage 2 with ridge penalty `lambda` (shorthand).
    ///
    /// # Errors
    /// As [`Ridge::new`].
    pub fn linear(mut self, lambda: f64) -> Result<Self> {
        self.regressor = RegressorConfig::Linear(Ridge::new(lambda)?);
        Ok(self)
    }
    /// Number of training simulations m.
    pub fn simulations(mut self, m: usize) -> Self {
        self.simulations = m;
        self
    }
    /// How the training parameters fill the prior box.
    pub fn sampling(mut self, sampling: Sampling) -> Self {
        self.sampling = Some(sampling);
        self
    }
    /// Seed of every random choice of the run.
    pub fn seed(mut self, seed: u64) -> Self {
        self.settings.seed = Some(seed);
        self
    }
    /// Fresh simulations for the conformal intervals (0: none).
    pub fn calibration(mut self, count: usize) -> Self {
        self.settings.calibration = count;
        self
    }
    /// Interval miscoverage level alpha.
    pub fn alpha(mut self, alpha: f64) -> Self {
        self.settings.alpha = alpha;
        self
    }
    /// Fresh simulations r for the validation report, exactly (0: none);
    /// a later [`certify_within`](Self::certify_within) makes them the
    /// first round.
    pub fn validation(mut self, r: usize) -> Self {
        self.settings.validation = r;
        self.settings.certify_within = None;
        self
    }
    /// Grow the validation, from its first round of
    /// [`validation`](Self::validation) records, until every certified RMSE
    /// is at most `k` times the observed one, at most `max` records
    /// ([`RunSettings::certify_within`]; the default, from 1000 records,
    /// with `k` 1.2).
    pub fn certify_within(mut self, k: f64, max: usize) -> Self {
        self.settings.certify_within = Some(k);
        self.settings.max_validation = max;
        self
    }
    /// Confidence parameter delta of the Hoeffding bound.
    pub fn delta(mut self, delta: f64) -> Self {
        self.settings.delta = delta;
        self
    }
    /// Share of failed simulations tolerated in each chart.
    pub fn max_failure_fraction(mut self, fraction: f64) -> Self {
        self.settings.max_failure_fraction = fraction;
        self
    }

    /// Every run setting at once (seed, calibration, validation, alpha,
    /// delta, failure allowance).
    pub fn settings(mut self, settings: RunSettings) -> Self {
        self.settings = settings;
        self
    }

    /// Where the records come from (default: simulated as the run goes).
    pub fn records(mut self, records: RecordSource<'a>) -> Self {
        self.records = records;
        self
    }

    /// Tell `progress` how the run advances (default: nothing is shown).
    ///
    /// ```
    /// use std::sync::atomic::{AtomicUsize, Ordering};
    /// use twostage::{Progress, Stage, TwoStage};
    /// use twostage::models::Benchmark;
    ///
    /// #[derive(Default)]
    /// struct Count(AtomicUsize);
    /// impl Progress for Count {
    ///     fn advance(&self, _stage: Stage, done: usize) {
    ///         self.0.fetch_add(done, Ordering::Relaxed);
    ///     }
    /// }
    ///
    /// let model = Benchmark::builder().n_samples(200).build()?;
    /// let count = Count::default();
    /// TwoStage::builder(&model)
    ///     .simulations(100)
    ///     .calibration(30)
    ///     .validation(20)
    ///     .linear(1e-6)?
    ///     .progress(&count)
    ///     .train()?;
    /// assert_eq!(count.0.load(Ordering::Relaxed), 150);
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn progress(mut self, progress: &'a dyn Progress) -> Self {
        self.progress = progress;
        self
    }

    /// Compress the training records, fit stage 2, then calibrate the
    /// intervals and validate on the calibration and validation records,
    /// whatever their source ([`Self::records`]): [`Self::prepare`], then
    /// [`Run::fit`].
    ///
    /// Simulated calibration and validation parameters are drawn i.i.d.
    /// uniform from the prior whatever the training design, because
    /// Theorem 1 and the conformal guarantee assume independent draws.
    /// Shards bring their own seed and sizes; a seed set on the builder
    /// must agree with theirs.
    ///
    /// # Errors
    /// Invalid settings, a chart too small for its held-out records, too
    /// many failed records, a file problem of the source
    /// ([`Error::Source`]), or a failed fit.
    pub fn train(self) -> Result<Estimator> {
        self.prepare()?.fit()
    }

    /// The run this builder asks for: a shard chart's seed and sizes
    /// adopted (checked against the model and the builder's seed), the
    /// settings checked, the records opened. Its [`Run::fit`] is
    /// [`Self::train`]; a search fits many structures on its records and
    /// ends with [`Run::finish`].
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::Benchmark;
    ///
    /// let model = Benchmark::builder().n_samples(200).build()?;
    /// let run = TwoStage::builder(&model).simulations(100).seed(4).prepare()?;
    /// assert_eq!(run.seed(), 4);
    /// assert_eq!(run.records().training_count(), 100);
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// Invalid settings, fewer than 10 simulations, shards of another model
    /// or seed, or a source that cannot be opened.
    pub fn prepare(self) -> Result<Run<'a, S>> {
        let builder = self.adopting_source()?;
        builder.settings.check()?;
        if builder.records.simulates() && builder.simulations < 10 {
            return Err(Error::setting(
                "simulations",
                builder.simulations.to_string(),
                "at least 10",
            ));
        }
        let records = builder.open_records()?;
        let mut settings = builder.settings;
        settings.seed = Some(settings.seed_or_default());
        Ok(Run::new(
            builder.simulator,
            (builder.compressor, builder.regressor, builder.posterior),
            settings,
            records,
            builder.progress,
        ))
    }

    /// The builder with the seed and sizes of the shards it trains on
    /// (checked against the model and the builder's seed), or as it is.
    fn adopting_source(mut self) -> Result<Self> {
        let RecordSource::Shards(chart) = self.records else {
            return Ok(self);
        };
        chart.check_model(self.simulator.spec())?;
        let plan = chart.plan();
        if let Some(seed) = self.settings.seed.filter(|s| *s != plan.seed) {
            return Err(twostage_sources::Error::Shards {
                what: chart.pattern().to_string(),
                message: format!(
                    "the shards were simulated with seed {}, the training asks for seed {seed}: \
                     train with --seed {} (or leave it out)",
                    plan.seed, plan.seed
                ),
            }
            .into());
        }
        self.settings.seed = Some(plan.seed);
        self.simulations = plan.counts.training;
        self.settings.calibration = plan.counts.calibration;
        self.settings.validation = plan.counts.validation;
        let sampling = self.training_prior().sampling();
        if sampling != chart.sampling() {
            return Err(twostage_sources::Error::Shards {
                what: chart.pattern().to_string(),
                message: format!(
                    "the shards were drawn by {} sampling, the training asks for {sampling}",
                    chart.sampling()
                ),
            }
            .into());
        }
        Ok(self)
    }

    /// The builder's record source, opened for its run.
    fn open_records(&self) -> Result<Records<'a, S>> {
        Ok(Records::open(
            self.simulator,
            self.records,
            RunShape {
                training_prior: self.training_prior(),
                counts: twostage_sources::RoleCounts::new(
                    self.simulations,
                    self.settings.calibration,
                    self.settings.validation,
                ),
                seed: self.seed_value(),
                max_failure_fraction: self.settings.max_failure_fraction,
                progress: self.progress,
            },
        )?)
    }

    /// The prior the training chart is drawn from: the model's, with the
    /// builder's sampling if one was set.
    fn training_prior(&self) -> twostage_models::Prior {
        let prior = self.simulator.spec().prior().clone();
        match self.sampling {
            Some(s) => prior.with_sampling(s),
            None => prior,
        }
    }

    /// The seed of every random choice.
    fn seed_value(&self) -> u64 {
        self.settings.seed_or_default()
    }
}

/// What the builder holds so far, for a search that sizes its run before
/// preparing it.
impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// The simulator.
    ///
    /// ```
    /// # use twostage::{TwoStage, models::{Benchmark, Simulator}};
    /// let model = Benchmark::new();
    /// assert_eq!(TwoStage::builder(&model).simulator().spec().name(), model.spec().name());
    /// ```
    pub fn simulator(&self) -> &'a S {
        self.simulator
    }

    /// The run settings as set so far (a shard chart's seed and sizes are
    /// adopted only by [`Self::prepare`]).
    ///
    /// ```
    /// # use twostage::{TwoStage, models::Benchmark};
    /// let model = Benchmark::new();
    /// assert_eq!(TwoStage::builder(&model).calibration(7).run_settings().calibration, 7);
    /// ```
    pub fn run_settings(&self) -> &RunSettings {
        &self.settings
    }

    /// Where the records come from.
    ///
    /// ```
    /// # use twostage::{TwoStage, models::Benchmark};
    /// assert!(TwoStage::builder(&Benchmark::new()).record_source().simulates());
    /// ```
    pub fn record_source(&self) -> RecordSource<'a> {
        self.records
    }
}
