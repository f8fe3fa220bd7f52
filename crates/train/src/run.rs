//! One training run, prepared from a builder: the seam between what a
//! training is asked for and how its stages are chosen. [`Run::fit`] fits
//! the builder's one structure; a search (the automatic design) fits many
//! on [`Run::records`] and ships its winner through [`Run::finish`].

use crate::Result;
use twostage_estimator::space::to_learning_space;
use twostage_estimator::{Estimator, TrainingInfo};
use twostage_fit::{FittedRegressor, MixtureDensity, RegressorConfig};
use twostage_models::{InputFamily, Simulator};
use twostage_sources::{ChartRole, ForModel, Progress, Records, Stage};
use twostage_validate::{CALIBRATION_DRAWS, rounds_listed};

use crate::settings::RunSettings;
use std::time::{Duration, Instant};
use twostage_compress::CompressorConfig;
use twostage_sources::CompressedChart;

/// What the fitted stages were trained on, for the estimator's record.
#[derive(Debug, Clone)]
pub struct TrainedOn<'f> {
    /// The features of the records the network was fitted on.
    pub features: ndarray::ArrayView2<'f, f64>,
    /// Their parameters, row for row (a conditional density of the
    /// parameters, where asked, is fitted on both).
    pub thetas: ndarray::ArrayView2<'f, f64>,
    /// Training simulations, failed ones included.
    pub simulations: usize,
    /// Training simulations that failed and were dropped.
    pub failures: usize,
    /// The stage-2 method as configured.
    pub regressor: RegressorConfig,
}

/// A training run: settings checked, seed fixed, records opened. Made by
/// [`TwoStage::prepare`](crate::TwoStage::prepare).
pub struct Run<'a, S: ?Sized> {
    simulator: &'a S,
    compressor: CompressorConfig,
    regressor: RegressorConfig,
    posterior: Option<MixtureDensity>,
    settings: RunSettings,
    records: Records<'a, S>,
    progress: &'a dyn Progress,
    /// The end of the run's time budget: a validation grown toward its
    /// certificate takes no more records than the time left affords.
    deadline: Option<Instant>,
}

impl<S: ?Sized> std::fmt::Debug for Run<'_, S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Run")
            .field("compressor", &self.compressor)
            .field("regressor", &self.regressor)
            .field("posterior", &self.posterior)
            .field("settings", &self.settings)
            .finish_non_exhaustive()
    }
}

impl<'a, S: Simulator + ?Sized> Run<'a, S> {
    pub(crate) fn new(
        simulator: &'a S,
        (compressor, regressor, posterior): (
            CompressorConfig,
            RegressorConfig,
            Option<MixtureDensity>,
        ),
        settings: RunSettings,
        records: Records<'a, S>,
        progress: &'a dyn Progress,
    ) -> Self {
        Self {
            simulator,
            compressor,
            regressor,
            posterior,
            settings,
            records,
            progress,
            deadline: None,
        }
    }

    /// The run under a time budget ending at `deadline`: a validation
    /// grown toward its certificate takes no more records than the time
    /// left affords (the run's outcome then depends on the machine, as
    /// the budget's search does).
    pub fn with_deadline(mut self, deadline: Option<Instant>) -> Self {
        self.deadline = deadline;
        self
    }

    /// The simulator.
    pub fn simulator(&self) -> &'a S {
        self.simulator
    }

    /// The seed of every random choice of the run.
    pub fn seed(&self) -> u64 {
        self.settings.seed_or_default()
    }

    /// The run's settings, its seed fixed and, for shards, their sizes.
    pub fn settings(&self) -> &RunSettings {
        &self.settings
    }

    /// The progress observer.
    pub fn progress(&self) -> &'a dyn Progress {
        self.progress
    }

    /// The run's records, each role's compressed on request.
    pub fn records(&self) -> &Records<'a, S> {
        &self.records
    }

    /// Compress the training records with the builder's compressor, fit
    /// its stage 2 on them, then [`Self::finish`].
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::Benchmark;
    ///
    /// let model = Benchmark::builder().n_samples(200).build()?;
    /// let builder = || TwoStage::builder(&model).simulations(100).calibration(0).validation(0).linear(1e-6);
    /// let trained = builder()?.train()?;
    /// let fitted = builder()?.prepare()?.fit()?;
    /// assert_eq!(trained.to_bytes()?, fitted.to_bytes()?);
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// A compressor that does not fit the model or its records, too many
    /// failed records, or a failed fit.
    pub fn fit(&self) -> Result<Estimator> {
        let compressor = self
            .records
            .prepare(self.compressor.for_model(self.simulator.spec())?)?;
        let training = self
            .records
            .compressed(ChartRole::Training, &compressor)?
            .unwrap_or_default();
        self.progress.begin(Stage::Fitting, 0);
        let targets = to_learning_space(
            training.thetas.view(),
            self.simulator.spec().prior().marginals(),
        );
        let regressor = self
            .regressor
            .fit(training.features.view(), targets.view(), self.seed());
        self.progress.end(Stage::Fitting);
        self.finish(
            compressor,
            regressor?,
            TrainedOn {
                features: training.features.view(),
                thetas: training.thetas.view(),
                simulations: training.total(),
                failures: training.failures.len(),
                regressor: self.regressor.clone(),
            },
        )
    }

    /// Assemble the estimator from its fitted stages, then calibrate its
    /// intervals and validate it on the calibration and validation records
    /// of the run.
    ///
    /// # Errors
    /// Held-out records that cannot be compressed or estimated, or
    /// calibration and validation settings out of range.
    pub fn finish(
        &self,
        compressor: CompressorConfig,
        regressor: FittedRegressor,
        trained: TrainedOn<'_>,
    ) -> Result<Estimator> {
        let spec = self.simulator.spec();
        let training = TrainingInfo {
            model: spec.name().to_string(),
            simulations: trained.simulations,
            failures: trained.failures,
            seed: self.seed(),
            sampling: self.records.sampling(),
            regressor: trained.regressor,
            version: env!("CARGO_PKG_VERSION").to_string(),
        };
        let mut estimator =
            Estimator::from_stages(spec, compressor, regressor, training, trained.features);
        if let Some(density) = &self.posterior {
            self.progress.begin(Stage::Fitting, 0);
            let supports: Vec<_> = spec
                .prior()
                .marginals()
                .iter()
                .map(|m| m.support())
                .collect();
            let fitted =
                density
                    .seeded(self.seed())
                    .fit(trained.features, trained.thetas, &supports);
            self.progress.end(Stage::Fitting);
            let fitted = fitted?;
            let tried = density.candidates();
            if tried.len() > 1 {
                self.progress.note(&format!(
                    "posterior: {} components, the lowest held-out negative log-likelihood of \
                     {tried:?} ({:.4})",
                    fitted.shape().components,
                    fitted.best_restart().held_out_nll
                ));
            }
            if fitted.stopped_at_deadline() {
                self.progress.note(
                    "posterior: its fit was stopped at the time budget's end, calibrated on \
                     held-out records as it is; a larger budget trains it further",
                );
            }
            estimator = estimator.with_posterior(fitted)?;
        }
        // The held-out records are fresh draws of the training's
        // experiments: their inputs span the family the estimator speaks
        // for.
        let mut inputs: Option<InputFamily> = None;
        let mut include = |chart: &twostage_sources::CompressedChart| {
            if let Some(family) = &chart.inputs {
                match inputs.as_mut() {
                    Some(all) => all.merge(family),
                    None => inputs = Some(family.clone()),
                }
            }
        };
        if let Some(chart) = self
            .records
            .compressed(ChartRole::Calibration, estimator.compressor())?
        {
            include(&chart);
            estimator.calibrate_posterior(chart.thetas.view(), chart.features.view())?;
            estimator.calibrate(
                chart.thetas.view(),
                chart.features.view(),
                self.settings.alpha,
                self.seed(),
            )?;
        }
        let started = Instant::now();
        if let Some(mut chart) = self
            .records
            .compressed(ChartRole::Validation, estimator.compressor())?
        {
            include(&chart);
            estimator.validate(
                chart.thetas.view(),
                chart.features.view(),
                self.settings.delta,
            )?;
            // The posterior's calibration on the first round's records,
            // said beside the certificate (the file keeps the report, not
            // this): a grown validation would cost it draws per record.
            if let Some(calibration) = estimator.posterior_calibration(
                chart.thetas.view(),
                chart.features.view(),
                CALIBRATION_DRAWS,
                self.seed(),
            )? {
                self.progress
                    .note(calibration.describe(estimator.param_names()).trim_end());
            }
            self.certify_within(&mut estimator, &mut chart, started.elapsed())?;
        }
        Ok(estimator.with_input_family(inputs))
    }

    /// Grows the validation `chart` (validated on already, in `took`)
    /// until every certified RMSE is within the settings' multiple of the
    /// observed one, each round as many records as the last predicts
    /// ([`ValidationReport::next_round`]), then validates `estimator` on
    /// all of them; said in a note either way. Under the run's deadline a
    /// round takes as many records as the time left affords. Stops short,
    /// and says so, at the settings' most records, at a source whose
    /// records cannot grow, or where the time left affords too few.
    fn certify_within(
        &self,
        estimator: &mut Estimator,
        chart: &mut CompressedChart,
        mut took: Duration,
    ) -> Result<()> {
        let Some(k) = self.settings.certify_within else {
            return Ok(());
        };
        let most = self.settings.max_validation;
        let mut rounds = vec![chart.total()];
        let ended = loop {
            let Some(report) = estimator.validation() else {
                return Ok(());
            };
            let ratio = report.certified_ratio();
            let r = chart.total();
            if ratio <= k {
                break Ended::Met(ratio);
            }
            let wanted = report.records_for_ratio(k);
            if !self.records.grows(ChartRole::Validation) {
                break Ended::Fixed(ratio, wanted);
            }
            if r >= most {
                break Ended::Most(ratio, wanted);
            }
            let mut next = report.next_round(k, most);
            if let Some(deadline) = self.deadline {
                // As many records as the time left affords at the last
                // round's pace (a tenth of it kept for validating them):
                // the bound holds at every r, so a shorter round still
                // tightens it.
                let pace = took.as_secs_f64() / rounds.last().map_or(1, |&n| n.max(1)) as f64;
                let left = deadline.saturating_duration_since(Instant::now());
                let affordable = (0.9 * left.as_secs_f64() / pace.max(1e-12)).min(most as f64);
                next = next.min(r.saturating_add(affordable as usize));
                if next <= r + r.div_ceil(100) {
                    break Ended::Deadline(ratio, wanted);
                }
            }
            let started = Instant::now();
            self.records
                .grow(ChartRole::Validation, estimator.compressor(), chart, next)?;
            estimator.validate(
                chart.thetas.view(),
                chart.features.view(),
                self.settings.delta,
            )?;
            took = started.elapsed();
            rounds.push(next - r);
        };
        let r = chart.total();
        let records = |wanted: Option<u64>| match wanted {
            Some(n) => format!("about {n} records would bring it within {k}"),
            None => "no number of records would: an observed error is 0".to_string(),
        };
        let note = match ended {
            Ended::Met(ratio) if rounds.len() == 1 => format!(
                "certificate within {ratio:.3} times the observed RMSE on the first {r} \
                 validation records (asked: {k})"
            ),
            Ended::Met(ratio) => format!(
                "validation grown to r = {r} records (rounds of {}) until every certified RMSE \
                 is within {k} times the observed: {ratio:.3}",
                rounds_listed(&rounds)
            ),
            Ended::Fixed(ratio, wanted) => format!(
                "the certificate is {ratio:.3} times the observed RMSE on the {r} validation \
                 records read; {} (records read from charts or shards cannot grow: simulate \
                 a larger validation chart)",
                records(wanted)
            ),
            Ended::Most(ratio, wanted) => format!(
                "the certificate is {ratio:.3} times the observed RMSE on r = {r} validation \
                 records, the most allowed (rounds of {}); {}: raise the most",
                rounds_listed(&rounds),
                records(wanted)
            ),
            Ended::Deadline(ratio, wanted) => format!(
                "the certificate is {ratio:.3} times the observed RMSE on r = {r} validation \
                 records (rounds of {}), as many as the time budget afforded; {}",
                rounds_listed(&rounds),
                records(wanted)
            ),
        };
        self.progress.note(&note);
        Ok(())
    }
}

/// How a grown validation ended: its certified-to-observed ratio, and
/// where short, the records the last round predicts.
enum Ended {
    Met(f64),
    Fixed(f64, Option<u64>),
    Most(f64, Option<u64>),
    Deadline(f64, Option<u64>),
}
