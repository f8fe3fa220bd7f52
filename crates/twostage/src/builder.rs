//! Training: the `TwoStage` builder (the presets are in the per-model
//! table, `profile.rs`).

use std::time::Instant;

use twostage_compress::Compressor;
use twostage_fit::Ridge;
use twostage_models::{IoData, Sampling, Simulator, StreamPurpose, random_permutation, stream_rng};
use twostage_validate::{ConformalIntervals, ValidationReport};

use crate::adaptive::{AdaptiveIntervals, MIN_ADAPTIVE_CALIBRATION};
use crate::chart::{
    CompressedChart, ExperimentFailure, StoredChart, compress_chart_observed, simulate_records,
};
use crate::chart_file::ChartFiles;
use crate::config::{CompressorConfig, FittedRegressor, RegressorConfig};
use crate::envelope::FeatureEnvelope;
use crate::error::{Error, Result};
use crate::estimator::{Estimator, RecordShape, SignalNames, TrainingInfo};
use crate::profile::paper_benchmark;
use crate::progress::{Progress, Silent, Stage};
use crate::shard::{ChartRole, ShardedChart};
use crate::space::to_learning_space;

/// The choices of one training run, reusable across simulators.
#[derive(Debug, Clone, PartialEq)]
pub struct Preset {
    /// Stage-1 compressor.
    pub compressor: CompressorConfig,
    /// Stage-2 method.
    pub regressor: RegressorConfig,
    /// Training simulations m.
    pub simulations: usize,
}

/// What the fitted stages were trained on, for the estimator's record.
pub(crate) struct TrainedOn<'f> {
    pub(crate) features: ndarray::ArrayView2<'f, f64>,
    pub(crate) simulations: usize,
    pub(crate) failures: usize,
    pub(crate) sampling: String,
    pub(crate) regressor: RegressorConfig,
}

/// Where calibration and validation records come from.
#[derive(Clone, Copy)]
pub(crate) enum Fresh<'c> {
    /// Fresh simulations, as many as the builder says.
    Simulate,
    /// Compressed charts made elsewhere (held out of a chart, or their own).
    Given {
        calibration: Option<&'c CompressedChart>,
        validation: Option<&'c CompressedChart>,
    },
}

/// Truths, estimates and features of a compressed chart.
fn given_estimates(
    estimator: &Estimator,
    chart: &CompressedChart,
) -> Result<(
    ndarray::Array2<f64>,
    ndarray::Array2<f64>,
    ndarray::Array2<f64>,
)> {
    let estimates = estimator.predict_features(chart.features.view())?;
    Ok((chart.thetas.clone(), estimates, chart.features.clone()))
}

/// Streams of the timing pilot, apart from the training chart's.
const PILOT_SEED: u64 = 0x0050_494c_4f54; // "PILOT"

/// Builder of a two-stage estimator for one simulator.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `compressor` | ARX(5, 5) | any [`CompressorConfig`] |
/// | `regressor` | MLP with 10 tanh units, LM | any [`RegressorConfig`] |
/// | `simulations` (m) | 2000 | >= 10 |
/// | `sampling` | the prior's own | [`Sampling`] of the training chart |
/// | `seed` | 0 | any |
/// | `calibration` | 500 | fresh simulations for conformal intervals; 0 disables |
/// | `alpha` | 0.1 | interval miscoverage, in (0, 1) |
/// | `validation` (r) | 500 | fresh simulations for the report; 0 disables |
/// | `delta` | 1e-3 | confidence of the Hoeffding bound, in (0, 1) |
/// | `max_failure_fraction` | 0.01 | share of failed simulations tolerated |
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
    seed: u64,
    calibration: usize,
    alpha: f64,
    validation: usize,
    delta: f64,
    max_failure_fraction: f64,
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
            simulations: 2000,
            sampling: None,
            seed: 0,
            calibration: 500,
            alpha: 0.1,
            validation: 500,
            delta: 1e-3,
            max_failure_fraction: 0.01,
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
        self.seed = seed;
        self
    }
    /// Fresh simulations for the conformal intervals (0: none).
    pub fn calibration(mut self, count: usize) -> Self {
        self.calibration = count;
        self
    }
    /// Interval miscoverage level alpha.
    pub fn alpha(mut self, alpha: f64) -> Self {
        self.alpha = alpha;
        self
    }
    /// Fresh simulations r for the validation report (0: none).
    pub fn validation(mut self, r: usize) -> Self {
        self.validation = r;
        self
    }
    /// Confidence parameter delta of the Hoeffding bound.
    pub fn delta(mut self, delta: f64) -> Self {
        self.delta = delta;
        self
    }
    /// Share of failed simulations tolerated in each chart.
    pub fn max_failure_fraction(mut self, fraction: f64) -> Self {
        self.max_failure_fraction = fraction;
        self
    }

    /// Tell `progress` how the run advances (default: nothing is shown).
    pub fn progress(mut self, progress: &'a dyn Progress) -> Self {
        self.progress = progress;
        self
    }

    fn check(&self) -> Result<()> {
        if self.simulations < 10 {
            return Err(Error::InvalidSetting {
                name: "simulations",
                value: self.simulations.to_string(),
                reason: "at least 10".into(),
            });
        }
        self.check_common()
    }

    /// The settings a run checks whether it simulates or reads its chart.
    fn check_common(&self) -> Result<()> {
        let invalid = |name: &'static str, value: String, reason: &str| {
            Err(Error::InvalidSetting {
                name,
                value,
                reason: reason.into(),
            })
        };
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return invalid("alpha", self.alpha.to_string(), "must lie in (0, 1)");
        }
        if !(self.delta > 0.0 && self.delta < 1.0) {
            return invalid("delta", self.delta.to_string(), "must lie in (0, 1)");
        }
        if !(0.0..1.0).contains(&self.max_failure_fraction) {
            return invalid(
                "max_failure_fraction",
                self.max_failure_fraction.to_string(),
                "must lie in [0, 1)",
            );
        }
        Ok(())
    }

    /// Simulate and compress the training chart, fit stage 2, then calibrate
    /// and validate on fresh simulations.
    ///
    /// Calibration and validation parameters are drawn i.i.d. uniform from
    /// the prior whatever the training design, because Theorem 1 and the
    /// conformal guarantee assume independent draws.
    ///
    /// # Errors
    /// Invalid settings, too many failed simulations, or a failed fit.
    pub fn train(self) -> Result<Estimator> {
        self.check()?;
        let training_prior = self.training_prior();
        let design = ChartRole::Training.design(&training_prior, self.simulations, self.seed)?;
        let compressor = self.calibrated_compressor(&design)?;
        let chart = compress_chart_observed(
            self.simulator,
            &compressor,
            &design,
            Stage::Training,
            self.max_failure_fraction,
            self.progress,
        )?;
        self.progress.begin(Stage::Fitting, 0);
        let targets = to_learning_space(chart.thetas.view(), training_prior.marginals());
        let regressor = self
            .regressor
            .fit(chart.features.view(), targets.view(), self.seed);
        self.progress.end(Stage::Fitting);
        let regressor = regressor?;
        self.finish(
            compressor,
            regressor,
            TrainedOn {
                features: chart.features.view(),
                simulations: self.simulations,
                failures: chart.failures.len(),
                sampling: format!("{:?}", training_prior.sampling()),
                regressor: self.regressor.clone(),
            },
            Fresh::Simulate,
        )
    }

    /// Train on a chart simulated elsewhere ([`ChartFiles`]) instead of
    /// simulating one: compress its records as they are read, fit stage 2,
    /// then calibrate and validate on `calibration` and `validation` charts
    /// when given, else on records held out of `chart` at random (seeded):
    /// as many as [`Self::calibration`] and [`Self::validation`] say. The
    /// certificate then covers records drawn as the chart's were, and the
    /// estimator's training record says where they came from.
    ///
    /// # Errors
    /// Invalid settings, a chart too small for its held-out parts, a file
    /// problem ([`Error::ChartFile`]), too many records that cannot be
    /// compressed, or a failed fit.
    pub fn train_on_chart(
        self,
        chart: &ChartFiles,
        calibration: Option<&ChartFiles>,
        validation: Option<&ChartFiles>,
    ) -> Result<Estimator> {
        let spec = self.simulator.spec();
        let m = chart.len();
        let held_validation = if validation.is_some() {
            0
        } else {
            self.validation
        };
        let held_calibration = if calibration.is_some() {
            0
        } else {
            self.calibration
        };
        let held = held_validation + held_calibration;
        if m < held + 10 {
            return Err(Error::InvalidSetting {
                name: "held-out records",
                value: format!("{held_validation} validation + {held_calibration} calibration"),
                reason: format!(
                    "the chart {} has {m} records: at least 10 must be left to train on (hold \
                     out fewer, or give separate validation and calibration charts)",
                    chart.dir().display()
                ),
            });
        }
        self.check_common()?;
        // Roles by a seeded permutation: 0 train, 1 calibration, 2 validation.
        let order = random_permutation(m, &mut stream_rng(self.seed, 0, StreamPurpose::Design));
        let mut role = vec![0u8; m];
        for (rank, &row) in order.iter().enumerate() {
            role[row as usize] = if rank < held_validation {
                2
            } else if rank < held {
                1
            } else {
                0
            };
        }
        let compressor = self.chart_compressor(chart, Some(&role))?;
        let mut parts = chart_parts(spec, &compressor, chart, Some(&role), 3)?;
        let (training, held_out) = parts.split_at_mut(1);
        let training = &training[0];
        for (part, stage) in [
            (&training, "training"),
            (&&held_out[0], "calibration"),
            (&&held_out[1], "validation"),
        ] {
            crate::chart::within_allowance(
                stage,
                &part.failures,
                part.total(),
                self.max_failure_fraction,
            )?;
        }
        let own = |given: Option<&ChartFiles>| -> Result<Option<CompressedChart>> {
            given
                .map(|c| {
                    let mut parts = chart_parts(spec, &compressor, c, None, 1)?;
                    let part = parts.swap_remove(0);
                    crate::chart::within_allowance(
                        "given",
                        &part.failures,
                        part.total(),
                        self.max_failure_fraction,
                    )?;
                    Ok(part)
                })
                .transpose()
        };
        let calibration_chart = match own(calibration)? {
            Some(c) => Some(c),
            None if held_calibration > 0 => Some(held_out[0].clone()),
            None => None,
        };
        let validation_chart = match own(validation)? {
            Some(c) => Some(c),
            None if held_validation > 0 => Some(held_out[1].clone()),
            None => None,
        };
        self.progress.begin(Stage::Fitting, 0);
        let targets = to_learning_space(training.thetas.view(), spec.prior().marginals());
        let regressor = self
            .regressor
            .fit(training.features.view(), targets.view(), self.seed);
        self.progress.end(Stage::Fitting);
        let source = |given: Option<&ChartFiles>, held: usize| match given {
            Some(c) => format!("the chart {}", c.describe()),
            None if held > 0 => format!("{held} records held out of it at random"),
            None => "none".into(),
        };
        self.finish(
            compressor,
            regressor?,
            TrainedOn {
                features: training.features.view(),
                simulations: training.total(),
                failures: training.failures.len(),
                sampling: format!(
                    "the chart {} (calibration: {}; validation: {})",
                    chart.describe(),
                    source(calibration, held_calibration),
                    source(validation, held_validation)
                ),
                regressor: self.regressor.clone(),
            },
            Fresh::Given {
                calibration: calibration_chart.as_ref(),
                validation: validation_chart.as_ref(),
            },
        )
    }

    /// Train on a chart simulated in shards ([`ShardedChart`], e.g. by a
    /// Slurm array): the estimator is, bit for bit, the one [`Self::train`]
    /// gives with the shards' seed and sizes, since the shards hold the
    /// very experiments `train` would simulate. The seed, the number of
    /// simulations, and the calibration and validation sizes come from the
    /// shards; the builder's must agree where they were set.
    ///
    /// # Errors
    /// Shards of another model, or compressed by another compressor than
    /// the builder's; a seed that differs; too many failed records; a
    /// failed fit; a damaged shard ([`Error::Shards`]).
    pub fn train_on_shards(mut self, chart: &ShardedChart) -> Result<Estimator> {
        chart.check_model(self.simulator.spec())?;
        let plan = chart.plan();
        if self.seed != plan.seed {
            return Err(Error::Shards {
                what: chart.pattern().to_string(),
                message: format!(
                    "the shards were simulated with seed {}, the training asks for seed {}: \
                     train with --seed {} (or leave it out)",
                    plan.seed, self.seed, plan.seed
                ),
            });
        }
        let [m, calibration, validation] = plan.counts;
        self.simulations = m;
        self.calibration = calibration;
        self.validation = validation;
        self.check()?;
        let training_prior = self.training_prior();
        let sampling = format!("{:?}", training_prior.sampling());
        if sampling != chart.sampling() {
            return Err(Error::Shards {
                what: chart.pattern().to_string(),
                message: format!(
                    "the shards were drawn by {} sampling, the training asks for {sampling}",
                    chart.sampling()
                ),
            });
        }
        let mut compressor = self.shaped_compressor()?;
        if let Some(spec_text) = &plan.compressor {
            let stored: CompressorConfig = spec_text.parse()?;
            let stored = stored.for_shape(
                self.simulator.spec().input_names().len(),
                self.simulator.spec().output_names().len(),
                self.simulator.spec().n_samples(),
            )?;
            if stored.to_string() != compressor.to_string() {
                return Err(Error::Shards {
                    what: chart.pattern().to_string(),
                    message: format!(
                        "the shards hold features of {spec_text} ({stored}), the training asks \
                         for {compressor}: train with --compress {spec_text} (or simulate raw \
                         shards)"
                    ),
                });
            }
        } else if compressor.records_to_prepare() > 0 {
            let records = chart.first_training_records(compressor.records_to_prepare())?;
            compressor = compressor.prepared(&records)?;
        }
        let part = |role: ChartRole, stage: &'static str| -> Result<CompressedChart> {
            let compressed = chart.compressed(role, &compressor)?;
            crate::chart::within_allowance(
                stage,
                &compressed.failures,
                compressed.total(),
                self.max_failure_fraction,
            )?;
            Ok(compressed)
        };
        let training = part(ChartRole::Training, Stage::Training.label())?;
        let calibration = (calibration > 0)
            .then(|| part(ChartRole::Calibration, Stage::Calibration.label()))
            .transpose()?;
        let validation = (validation > 0)
            .then(|| part(ChartRole::Validation, Stage::Validation.label()))
            .transpose()?;
        self.progress.begin(Stage::Fitting, 0);
        let targets = to_learning_space(training.thetas.view(), training_prior.marginals());
        let regressor = self
            .regressor
            .fit(training.features.view(), targets.view(), self.seed);
        self.progress.end(Stage::Fitting);
        self.finish(
            compressor,
            regressor?,
            TrainedOn {
                features: training.features.view(),
                simulations: m,
                failures: training.failures.len(),
                sampling,
                regressor: self.regressor.clone(),
            },
            Fresh::Given {
                calibration: calibration.as_ref(),
                validation: validation.as_ref(),
            },
        )
    }

    /// The compressor, prepared (PCA directions, NARX scales) on the first
    /// training records of a chart when it needs that.
    fn chart_compressor(
        &self,
        chart: &ChartFiles,
        role: Option<&[u8]>,
    ) -> Result<CompressorConfig> {
        let compressor = self.shaped_compressor()?;
        let count = compressor.records_to_prepare();
        if count == 0 {
            return Ok(compressor);
        }
        // The first `count` training rows of truth.csv, whatever data.csv's order.
        let wanted: Vec<usize> = (0..chart.len())
            .filter(|row| role.is_none_or(|r| r[*row] == 0))
            .take(count)
            .collect();
        let mut first: Vec<(usize, IoData)> = Vec::with_capacity(wanted.len());
        chart.for_each_record(self.simulator.spec(), |row, record| {
            if wanted.binary_search(&row).is_ok() {
                first.push((row, record.clone()));
            }
            Ok(())
        })?;
        first.sort_by_key(|(row, _)| *row);
        let records: Vec<IoData> = first.into_iter().map(|(_, r)| r).collect();
        compressor.prepared(&records)
    }

    /// Assemble the estimator from its fitted stages, then calibrate its
    /// intervals and validate it on fresh simulations.
    pub(crate) fn finish(
        &self,
        compressor: CompressorConfig,
        regressor: FittedRegressor,
        trained: TrainedOn<'_>,
        fresh: Fresh<'_>,
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
                seed: self.seed,
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
        let calibration = match fresh {
            Fresh::Simulate if self.calibration > 0 => Some(self.fresh_estimates(
                &estimator,
                ChartRole::Calibration,
                self.calibration,
                Stage::Calibration,
            )?),
            Fresh::Given {
                calibration: Some(chart),
                ..
            } => Some(given_estimates(&estimator, chart)?),
            _ => None,
        };
        let intervals = if let Some((truth, estimates, features)) = calibration {
            let residuals = &truth - &estimates;
            if let Some(envelope) = estimator.envelope.as_mut() {
                envelope.recalibrate(features.view());
            }
            if residuals.nrows() >= MIN_ADAPTIVE_CALIBRATION {
                estimator.adaptive = Some(AdaptiveIntervals::calibrate(
                    features.view(),
                    residuals.view(),
                    self.alpha,
                    self.seed,
                )?);
            }
            Some(ConformalIntervals::calibrate(residuals.view(), self.alpha)?)
        } else {
            None
        };
        estimator.intervals = intervals.clone();
        let validation = match fresh {
            Fresh::Simulate if self.validation > 0 => Some(self.fresh_estimates(
                &estimator,
                ChartRole::Validation,
                self.validation,
                Stage::Validation,
            )?),
            Fresh::Given {
                validation: Some(chart),
                ..
            } => Some(given_estimates(&estimator, chart)?),
            _ => None,
        };
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
                self.delta,
                intervals,
            )?);
        }
        Ok(estimator)
    }

    /// The compressor with its own parameters fitted on the first
    /// experiments of the training design (an output PCA's directions, a
    /// NARX's signal scales), or as it is when it has none.
    fn calibrated_compressor(&self, design: &twostage_models::Design) -> Result<CompressorConfig> {
        let compressor = self.shaped_compressor()?;
        let count = compressor.records_to_prepare();
        if count == 0 {
            return Ok(compressor);
        }
        let chart = simulate_records(self.simulator, design, count, 0.0, None)?;
        compressor.prepared(&chart.records)
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
        let spec = self.simulator.spec();
        self.compressor.for_shape(
            spec.input_names().len(),
            spec.output_names().len(),
            spec.n_samples(),
        )
    }

    /// Truths and clipped estimates on `count` fresh i.i.d. simulations of
    /// the calibration or validation chart.
    fn fresh_estimates(
        &self,
        estimator: &Estimator,
        role: ChartRole,
        count: usize,
        stage: Stage,
    ) -> Result<(
        ndarray::Array2<f64>,
        ndarray::Array2<f64>,
        ndarray::Array2<f64>,
    )> {
        let design = role.design(self.simulator.spec().prior(), count, self.seed)?;
        let chart = compress_chart_observed(
            self.simulator,
            estimator.compressor(),
            &design,
            stage,
            self.max_failure_fraction,
            self.progress,
        )?;
        let estimates = estimator.predict_features(chart.features.view())?;
        Ok((chart.thetas, estimates, chart.features))
    }
}

impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// The simulator (read by the automatic design).
    pub(crate) fn simulator(&self) -> &'a S {
        self.simulator
    }

    /// The seed of every random choice.
    pub(crate) fn seed_value(&self) -> u64 {
        self.seed
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
            .design(pilot, self.seed ^ PILOT_SEED)?;
        let start = Instant::now();
        simulate_records(self.simulator, &design, pilot, 0.0, None)?;
        Ok((start.elapsed().as_secs_f64() / pilot as f64).max(1e-9))
    }

    /// Simulate m experiments of the training design and keep the records
    /// (failed experiments are dropped, within the failure allowance).
    pub(crate) fn stored_chart(&self, m: usize) -> Result<StoredChart> {
        let design = self.simulator.prior().design(m, self.seed)?;
        simulate_records(
            self.simulator,
            &design,
            m,
            self.max_failure_fraction,
            Some((Stage::Training, self.progress)),
        )
    }
}

/// A chart's records compressed, split into `parts` by `role` (all in part
/// 0 without one), in the file's order; records that cannot be compressed
/// are counted as failures of their part.
fn chart_parts(
    spec: &twostage_models::ModelSpec,
    compressor: &CompressorConfig,
    chart: &ChartFiles,
    role: Option<&[u8]>,
    parts: usize,
) -> Result<Vec<CompressedChart>> {
    let (q, n) = (spec.n_params(), compressor.n_features());
    // Features by truth.csv row, so that the order of data.csv never
    // changes the estimator.
    let mut features = vec![f64::NAN; chart.len() * n];
    let mut errors: Vec<Option<String>> = vec![None; chart.len()];
    let mut work = twostage_compress::Workspace::new();
    chart.for_each_record(spec, |row, record| {
        let alpha = &mut features[row * n..(row + 1) * n];
        if let Err(e) =
            compressor.compress_into(record.inputs(), record.outputs(), &mut work, alpha)
        {
            errors[row] = Some(e.to_string());
        }
        Ok(())
    })?;
    let mut out = Vec::with_capacity(parts);
    for p in 0..parts {
        let in_part = |row: &usize| role.is_none_or(|r| usize::from(r[*row]) == p);
        let kept: Vec<usize> = (0..chart.len())
            .filter(|row| in_part(row) && errors[*row].is_none())
            .collect();
        let failures = (0..chart.len())
            .filter(in_part)
            .filter_map(|row| {
                errors[row].as_ref().map(|e| ExperimentFailure {
                    index: row,
                    theta: chart.theta(row).to_vec(),
                    error: e.clone(),
                })
            })
            .collect();
        let thetas: Vec<f64> = kept
            .iter()
            .flat_map(|&r| chart.theta(r).iter().copied())
            .collect();
        let kept_features: Vec<f64> = kept
            .iter()
            .flat_map(|&r| features[r * n..(r + 1) * n].iter().copied())
            .collect();
        let rows = kept.len();
        let shape = |v: Vec<f64>, w: usize| {
            ndarray::Array2::from_shape_vec((rows, w), v)
                .unwrap_or_else(|_| unreachable!("rows * width values were kept"))
        };
        out.push(CompressedChart {
            thetas: shape(thetas, q),
            features: shape(kept_features, n),
            indices: kept,
            failures,
        });
    }
    Ok(out)
}
