//! Training: the `TwoStage` builder and its one `train`, whatever the
//! source of the records (the presets are in the per-model table,
//! `profile.rs`; the run's settings and their defaults in `settings.rs`).

use std::time::Instant;

use twostage_fit::Ridge;
use twostage_models::{Sampling, Simulator};
use twostage_validate::{ConformalIntervals, ValidationReport};

use crate::adaptive::{AdaptiveIntervals, MIN_ADAPTIVE_CALIBRATION};
use crate::envelope::FeatureEnvelope;
use crate::error::{Error, Result};
use crate::estimator::{Estimator, RecordShape, SignalNames, TrainingInfo};
use crate::settings::RunSettings;
use crate::space::to_learning_space;
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedRegressor, RegressorConfig};
use twostage_sources::ChartRole;
use twostage_sources::ForModel;
use twostage_sources::paper_benchmark;
use twostage_sources::{Preset, simulate_records};
use twostage_sources::{Progress, Silent, Stage};
use twostage_sources::{RecordSource, Records, RunShape};

/// What the fitted stages were trained on, for the estimator's record.
pub(crate) struct TrainedOn<'f> {
    pub(crate) features: ndarray::ArrayView2<'f, f64>,
    pub(crate) simulations: usize,
    pub(crate) failures: usize,
    pub(crate) sampling: String,
    pub(crate) regressor: RegressorConfig,
}

/// Streams of the timing pilot, apart from the training chart's.
const PILOT_SEED: u64 = 0x0050_494c_4f54; // "PILOT"

/// Builder of a two-stage estimator for one simulator.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `compressor` | ARX(5, 5) | any [`CompressorConfig`] |
/// | `regressor` | MLP with 10 tanh units, LM | any [`RegressorConfig`] |
/// | `simulations` (m) | 1500 | >= 10 |
/// | `sampling` | the prior's own | [`Sampling`] of the training chart |
/// | `records` | simulated | a [`RecordSource`]: simulated, chart files or shards |
/// | `seed`, `calibration`, `alpha`, `validation`, `delta`, `max_failure_fraction` | [`RunSettings::default`] | as [`RunSettings`] says |
///
/// The compressor, regressor and m are the paper's benchmark preset
/// ([`paper_benchmark`](crate::paper_benchmark)) until set.
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
    /// Fresh simulations r for the validation report (0: none).
    pub fn validation(mut self, r: usize) -> Self {
        self.settings.validation = r;
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
    /// whatever their source ([`Self::records`]).
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
        let run = self.adopting_source()?;
        run.settings.check()?;
        if run.records.simulates() && run.simulations < 10 {
            return Err(Error::InvalidSetting {
                name: "simulations",
                value: run.simulations.to_string(),
                reason: "at least 10".into(),
            });
        }
        let records = run.open_records()?;
        let compressor = records.prepare(run.shaped_compressor()?)?;
        let training = records
            .compressed(ChartRole::Training, &compressor)?
            .unwrap_or_default();
        run.progress.begin(Stage::Fitting, 0);
        let targets = to_learning_space(
            training.thetas.view(),
            run.simulator.spec().prior().marginals(),
        );
        let regressor =
            run.regressor
                .fit(training.features.view(), targets.view(), run.seed_value());
        run.progress.end(Stage::Fitting);
        run.finish(
            compressor,
            regressor?,
            TrainedOn {
                features: training.features.view(),
                simulations: training.total(),
                failures: training.failures.len(),
                sampling: records.sampling(),
                regressor: run.regressor.clone(),
            },
            &records,
        )
    }

    /// The builder with the seed and sizes of the shards it trains on
    /// (checked against the model and the builder's seed), or as it is.
    pub(crate) fn adopting_source(mut self) -> Result<Self> {
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
        let [m, calibration, validation] = plan.counts;
        self.settings.seed = Some(plan.seed);
        self.simulations = m;
        self.settings.calibration = calibration;
        self.settings.validation = validation;
        let sampling = format!("{:?}", self.training_prior().sampling());
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
    pub(crate) fn open_records(&self) -> Result<Records<'a, S>> {
        Ok(Records::open(
            self.simulator,
            self.records,
            RunShape {
                training_prior: self.training_prior(),
                counts: [
                    self.simulations,
                    self.settings.calibration,
                    self.settings.validation,
                ],
                seed: self.seed_value(),
                max_failure_fraction: self.settings.max_failure_fraction,
                progress: self.progress,
            },
        )?)
    }

    /// Assemble the estimator from its fitted stages, then calibrate its
    /// intervals and validate it on the calibration and validation records
    /// of `records`.
    pub(crate) fn finish(
        &self,
        compressor: CompressorConfig,
        regressor: FittedRegressor,
        trained: TrainedOn<'_>,
        records: &Records<'a, S>,
    ) -> Result<Estimator> {
        let spec = self.simulator.spec();
        let prior = spec.prior();
        let mut estimator = Estimator {
            param_names: spec.param_names().to_vec(),
            lower: prior.lower().to_vec(),
            upper: prior.upper().to_vec(),
            shape: RecordShape {
                n_samples: spec.n_samples(),
                n_inputs: spec.input_names().len(),
                n_outputs: spec.output_names().len(),
                sample_time: spec.sample_time(),
            },
            compressor,
            regressor,
            training: TrainingInfo {
                model: spec.name().to_string(),
                simulations: trained.simulations,
                failures: trained.failures,
                seed: self.seed_value(),
                sampling: trained.sampling,
                regressor: trained.regressor,
                version: env!("CARGO_PKG_VERSION").to_string(),
            },
            intervals: None,
            validation: None,
            envelope: FeatureEnvelope::fit(trained.features),
            adaptive: None,
            marginals: prior.marginals().to_vec(),
            signal_names: Some(SignalNames {
                inputs: spec.input_names().to_vec(),
                outputs: spec.output_names().to_vec(),
            }),
        };
        // Truths, estimates and features of the records of a role.
        let estimated = |role: ChartRole, estimator: &Estimator| -> Result<_> {
            records
                .compressed(role, estimator.compressor())?
                .map(|chart| {
                    let estimates = estimator.predict_features(chart.features.view())?;
                    Ok((chart.thetas, estimates, chart.features))
                })
                .transpose()
        };
        let calibration = estimated(ChartRole::Calibration, &estimator)?;
        let intervals = if let Some((truth, estimates, features)) = calibration {
            let residuals = &truth - &estimates;
            if let Some(envelope) = estimator.envelope.as_mut() {
                envelope.recalibrate(features.view());
            }
            if residuals.nrows() >= MIN_ADAPTIVE_CALIBRATION {
                estimator.adaptive = Some(AdaptiveIntervals::calibrate(
                    features.view(),
                    residuals.view(),
                    self.settings.alpha,
                    self.seed_value(),
                )?);
            }
            Some(ConformalIntervals::calibrate(
                residuals.view(),
                self.settings.alpha,
            )?)
        } else {
            None
        };
        estimator.intervals = intervals.clone();
        let validation = estimated(ChartRole::Validation, &estimator)?;
        if let Some((truth, estimates, features)) = validation {
            if let Some(adaptive) = estimator.adaptive.as_mut() {
                adaptive.validate(features.view(), (&truth - &estimates).view())?;
            }
            estimator.validation = Some(ValidationReport::new(
                spec.param_names(),
                truth.view(),
                estimates.view(),
                prior.lower(),
                prior.upper(),
                self.settings.delta,
                intervals,
            )?);
        }
        Ok(estimator)
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

    /// The compressor for the model's number of inputs and outputs.
    fn shaped_compressor(&self) -> Result<CompressorConfig> {
        Ok(self.compressor.for_model(self.simulator.spec())?)
    }
}

impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// The simulator (read by the automatic design).
    pub(crate) fn simulator(&self) -> &'a S {
        self.simulator
    }

    /// The seed of every random choice.
    pub(crate) fn seed_value(&self) -> u64 {
        self.settings.seed_or_default()
    }

    /// The progress observer.
    pub(crate) fn observer(&self) -> &'a dyn Progress {
        self.progress
    }

    /// Parallel throughput of the simulator, from a small timed pilot.
    pub(crate) fn pilot_seconds_per_simulation(&self) -> Result<f64> {
        let pilot = 64;
        let design = self
            .simulator
            .prior()
            .design(pilot, self.seed_value() ^ PILOT_SEED)?;
        let start = Instant::now();
        simulate_records(self.simulator, &design, pilot, 0.0, None)?;
        Ok((start.elapsed().as_secs_f64() / pilot as f64).max(1e-9))
    }

    /// The run's settings.
    pub(crate) fn settings_ref(&self) -> &RunSettings {
        &self.settings
    }

    /// Where the records come from.
    pub(crate) fn record_source(&self) -> RecordSource<'a> {
        self.records
    }
}
