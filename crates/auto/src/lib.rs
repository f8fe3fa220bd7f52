//! Automatic design: search stage-1 structures and network sizes by
//! validation error on simulated data, so that no human picks the ARX
//! order or the network (the paper leaves both to "a few trial-and-error
//! attempts").
//!
//! The chart is simulated once and its records kept; every candidate
//! compressor compresses them, every candidate network fits the same rows,
//! and all are scored on the same held-out rows. The winner is refitted on
//! the whole chart, then calibrated and validated on fresh simulations like
//! any trained estimator (so the final report is not biased by the
//! selection).
//!
//! The search trains through the training crate's public seam: it sizes
//! the chart from the builder ([`TwoStage::simulator`],
//! [`TwoStage::run_settings`]), prepares the run
//! ([`TwoStage::prepare`]), fits its candidates on the run's records, and
//! ships the winner through [`Run::finish`](twostage_train::Run::finish).
#![deny(missing_docs)]

use std::time::{Duration, Instant};

use twostage_estimator::{Error, Estimator, Result};
use twostage_models::Simulator;
use twostage_train::{RunSettings, TrainedOn, TwoStage};

use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;
use twostage_sources::ForModel;
use twostage_sources::Stage;
use twostage_sources::simulate_records;

mod candidates;
mod cost;
mod search;

use candidates::{candidate_compressors, network, output_transforms, pieces};
pub use search::{FinalFit, FinalFits};
use search::{Scope, Search, Winner};

/// How much the search may spend.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Budget {
    /// Wall-clock seconds for the whole search (chart, fits, refit;
    /// calibration and validation come on top). The chart size follows
    /// from a timed pilot, and candidates that would not finish in time are
    /// skipped, so the outcome depends on the machine.
    Seconds(f64),
    /// A chart of exactly this many simulations, and every candidate
    /// evaluated: the same seed gives the same estimator on any machine.
    Simulations(usize),
}

impl Budget {
    /// The budget in words, e.g. "a 120 s budget" or "5000 simulations".
    pub fn describe(&self) -> String {
        match self {
            Self::Seconds(t) => format!("a {t} s budget"),
            Self::Simulations(m) => format!("{m} simulations, every candidate"),
        }
    }
}

impl Default for Budget {
    /// Two minutes.
    fn default() -> Self {
        Self::Seconds(120.0)
    }
}

/// One candidate structure and how it scored.
#[derive(Debug, Clone, PartialEq)]
pub struct CandidateReport {
    /// Stage 1.
    pub compressor: String,
    /// Stage 2.
    pub regressor: String,
    /// Both stages as the command line writes them (`log+pca:8 mlp:20`),
    /// or as they read where a stage has no such form.
    pub design: String,
    /// Search round: 1 compares compressors with one network, 2 compares
    /// networks on the best compressors, 3 averages the winner's restarts.
    pub round: usize,
    /// RMSE per parameter on the held-out chart rows (empty when not run).
    pub rmse: Vec<f64>,
    /// Mean over parameters of RMSE / prior standard deviation (lower is
    /// better; 1 means nothing learned).
    pub score: f64,
    /// Seconds spent compressing and fitting it.
    pub seconds: f64,
    /// Chart rows its network was fitted on: all the fitting rows, or a
    /// screening share of them in round 1 of a large chart.
    pub fit_rows: usize,
    /// Whether it was scored, and why not if it was not.
    pub status: Status,
    /// How its network was trained (trainer, stop reason, restarts).
    pub trained_by: Option<String>,
}

/// Whether a candidate was scored, and why not if it was not.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// Fitted, and scored on the held-out rows.
    Scored,
    /// Not started: about `seconds` would have overrun the time budget.
    Skipped {
        /// Its estimated cost.
        seconds: f64,
    },
    /// Its stage 1 does not apply to these records (an autoregression of
    /// a noise-free decay is rank deficient, say): why.
    NotApplicable(String),
    /// Its fit went wrong: why.
    Failed(String),
}

impl Status {
    /// Whether the candidate has a score.
    ///
    /// ```
    /// assert!(twostage::auto::Status::Scored.is_scored());
    /// assert!(!twostage::auto::Status::Failed("diverged".into()).is_scored());
    /// ```
    pub fn is_scored(&self) -> bool {
        matches!(self, Self::Scored)
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Scored => write!(f, "scored"),
            Self::Skipped { seconds } => write!(
                f,
                "skipped: about {seconds:.0} s would overrun the time budget"
            ),
            Self::NotApplicable(why) => write!(f, "does not apply to these records: {why}"),
            Self::Failed(why) => write!(f, "failed: {why}"),
        }
    }
}

/// The result of [`AutoDesign::run`].
#[derive(Debug)]
pub struct AutoOutcome {
    /// The best candidate, refitted on the whole chart, calibrated and
    /// validated.
    pub estimator: Estimator,
    /// Every candidate, in the order tried.
    pub candidates: Vec<CandidateReport>,
    /// Index of the winner in `candidates`.
    pub best: usize,
    /// Simulations in the chart.
    pub simulations: usize,
    /// The simulations among them that failed (left out of every fit).
    pub failures: usize,
    /// Seconds of the search (without calibration and validation).
    pub search_seconds: f64,
    /// How the shipped network was fitted: as scored, anew, trained
    /// further, or both and the better shipped; on how many rows.
    pub final_fit: FinalFit,
    /// The round-2 winner's score at the run's seed and, where the budget
    /// allowed, at two other seeds: how much the seed alone moves it.
    pub seed_scores: Vec<f64>,
    /// The round-2 winner fitted on half its rows (how many, and its
    /// score), where the budget allowed: a learning curve's last step,
    /// which says whether more records would pay.
    pub half_rows: Option<(usize, f64)>,
    /// Simulations added after the search for the winner's final fit
    /// (counted in `simulations`), where more records pay and the time
    /// left afforded them.
    pub added_simulations: usize,
    /// How the round-2 winner's fit time grew with its rows (the exponent,
    /// from its half-rows and seed trials timed alone), where measured: the
    /// final fit's rows follow from it.
    pub rows_exponent: Option<f64>,
}

/// Whether a score of `half` on half the rows against `own` on all of them
/// says more records would pay: the learning curve still falls. Time a
/// search would leave unused then goes to more records, trained further
/// from the winner's fit, which cannot make it worse on held-out rows.
fn more_records_pay(half: f64, own: f64) -> bool {
    half > own
}

impl std::fmt::Display for AutoOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "automatic design on m = {} simulations ({:.1} s), held-out RMSE per candidate:",
            self.simulations, self.search_seconds
        )?;
        let fitted_rows = self.final_fit.rows();
        if self.final_fit.stopped() {
            writeln!(
                f,
                "(the winner's final fit on {fitted_rows} records was stopped at the time budget's \
                 end: it ships trained as far as it got from the fit it was scored with)"
            )?;
        } else if !matches!(self.final_fit, FinalFit::Compared { .. })
            && fitted_rows < self.simulations - self.failures
        {
            writeln!(
                f,
                "(the time budget left no room to refit the winner on the whole chart: it ships \
                 fitted on {} of its {} records)",
                fitted_rows, self.simulations
            )?;
        }
        if let [own, others @ ..] = self.seed_scores.as_slice()
            && !others.is_empty()
        {
            let (low, high) = others
                .iter()
                .fold((*own, *own), |(l, h), s| (l.min(*s), h.max(*s)));
            let listed: Vec<String> = others.iter().map(|s| format!("{s:.4}")).collect();
            writeln!(
                f,
                "the round-2 winner scores {own:.4} at the run's seed and {} at two others: \
                 the seed moves it by {:.1}%",
                listed.join(" and "),
                100.0 * (high - low) / own.max(f64::MIN_POSITIVE)
            )?;
        }
        if let (Some((rows, half)), Some(own)) = (self.half_rows, self.seed_scores.first()) {
            writeln!(
                f,
                "on half its records ({rows}) the round-2 winner scores {half:.4} against \
                 {own:.4}: more records would {}",
                // The seed alone moves a score by 1 to 2%.
                if half > 1.03 * own {
                    "pay"
                } else if more_records_pay(half, *own) {
                    "pay a little"
                } else {
                    "not pay"
                }
            )?;
        }
        if let Some(exponent) = self.rows_exponent {
            writeln!(
                f,
                "its fit time grows as rows^{exponent:.2} (half its rows and all of them, timed alone)"
            )?;
        }
        if self.added_simulations > 0 {
            writeln!(
                f,
                "so the winner's final fit took {} more simulations: fitted on {} records",
                self.added_simulations, fitted_rows
            )?;
        }
        if let FinalFit::Compared {
            fits:
                FinalFits {
                    compared,
                    further,
                    anew,
                },
            ..
        } = self.final_fit
        {
            writeln!(
                f,
                "on the last {compared} added records, seen by no fit, the winner trained further \
                 scores {further:.4} and fitted anew {anew:.4}: the {} ships",
                if anew < further {
                    "fit anew"
                } else {
                    "fit trained further"
                }
            )?;
        }
        for (i, c) in self.candidates.iter().enumerate() {
            let mark = if i == self.best { "*" } else { " " };
            let rmse: Vec<String> = c.rmse.iter().map(|r| format!("{r:.4e}")).collect();
            match &c.status {
                Status::Scored => writeln!(
                    f,
                    " {mark} {:<28} score {:.4}  RMSE [{}]  {:.1} s on {} rows{}",
                    c.design,
                    c.score,
                    rmse.join(", "),
                    c.seconds,
                    c.fit_rows,
                    c.trained_by
                        .as_ref()
                        .map_or_else(String::new, |t| format!("; {t}"))
                )?,
                status => writeln!(f, " {mark} {:<28} {status}", c.design)?,
            }
        }
        Ok(())
    }
}

/// Builder of an automatic design for one simulator; see [`AutoDesign::new`].
#[derive(Debug)]
pub struct AutoDesign<'a, S: ?Sized> {
    base: TwoStage<'a, S>,
    budget: Budget,
    compressors: Option<Vec<CompressorConfig>>,
    networks: Option<(RegressorConfig, Vec<RegressorConfig>)>,
    screening_rows: usize,
}

/// Largest chart a time budget chooses per second of budget: the default
/// search's fits, not its simulations, dominate its cost, and they grow
/// with m; on 2 cores they take about 100 s at m = 8000 (docs/accuracy.md),
/// so 120 s buys 8000 simulations and 300 s 20000. (16000 per 120 s was
/// tried: the refit then had time for only 6607 of them, 1.24 times the
/// Bayes RMSE against 1.21 to 1.29 at 8000.)
const SIMULATIONS_PER_BUDGET_SECOND: f64 = 8000.0 / 120.0;
/// Fitting rows round 1 uses at most: it only picks the compressors worth
/// round 2, and the best few are close (on the benchmark at m = 20000 the
/// ARX orders 2 to 4 score within 2% of each other, round 2's networks
/// move the score by 10%); the time saved goes to round 2 on every row.
const SCREENING_ROWS: usize = 4000;
/// Memory allowed for the stored records.
const MAX_CHART_BYTES: usize = 2 << 30;

impl<'a, S: Simulator + ?Sized> AutoDesign<'a, S> {
    /// An automatic design for `simulator`: the settings of the builder
    /// (seed, calibration, validation, progress...) apply, the compressor,
    /// regressor and m are searched.
    ///
    /// ```
    /// use twostage::{AutoDesign, Budget, RegressorConfig};
    /// use twostage::compress::Arx;
    /// use twostage::fit::MlpParams;
    /// use twostage::models::Benchmark;
    ///
    /// let model = Benchmark::builder().n_samples(300).build()?;
    /// let net = |h: usize| -> Result<RegressorConfig, twostage::Error> {
    ///     Ok(RegressorConfig::Mlp(MlpParams::new(&[h])?.restarts(2).check()?))
    /// };
    /// let outcome = AutoDesign::new(&model)
    ///     .budget(Budget::Simulations(400))
    ///     // A small search for the example; the defaults search more.
    ///     .compressors(vec![Arx::new(2, 2)?.into(), Arx::new(4, 4)?.into()])
    ///     .networks(net(6)?, vec![net(3)?])
    ///     .settings(|b| b.calibration(100).validation(100))
    ///     .run()?;
    /// // 2 compressors with one network, the other network on both, then
    /// // the winner's ARX with the record's level, and its restarts averaged.
    /// assert_eq!(outcome.candidates.len(), 6);
    /// let best = &outcome.candidates[outcome.best];
    /// assert!(outcome.candidates.iter().all(|c| !c.status.is_scored() || c.score >= best.score));
    /// println!("{outcome}");
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn new(simulator: &'a S) -> Self {
        Self {
            base: TwoStage::builder(simulator),
            budget: Budget::default(),
            compressors: None,
            networks: None,
            screening_rows: SCREENING_ROWS,
        }
    }
}

impl<'a, S: Simulator + ?Sized> AutoDesign<'a, S> {
    /// The search budget (default: 120 seconds).
    pub fn budget(mut self, budget: Budget) -> Self {
        self.budget = budget;
        self
    }

    /// Replace the round-1 compressors (default: ARX(n, n) for n = 2, 3, 4,
    /// 5, 6, 8, NARX(2, 2, 2), output PCA with 8, 12, 16 components).
    pub fn compressors(mut self, compressors: Vec<CompressorConfig>) -> Self {
        self.compressors = Some(compressors);
        self
    }

    /// Replace the networks: `first` for round 1, `others` for round 2
    /// (default: MLP `[20]`; then `[10]`, `[40]`, `[20, 20]`, and 4 pieces of `[20]`).
    pub fn networks(mut self, first: RegressorConfig, others: Vec<RegressorConfig>) -> Self {
        self.networks = Some((first, others));
        self
    }

    /// Fitting rows of round 1, which only ranks the compressors (default
    /// 4000): on a larger chart the round-1 fits see only this many, and
    /// round 2 fits its networks, the round-1 network among them, on every
    /// fitting row; only full fits compete for the win.
    pub fn screening_rows(mut self, rows: usize) -> Self {
        self.screening_rows = rows.max(1);
        self
    }

    /// Change the shared settings (seed, calibration, validation, alpha,
    /// delta, progress) through the ordinary builder.
    pub fn settings(mut self, f: impl FnOnce(TwoStage<'a, S>) -> TwoStage<'a, S>) -> Self {
        self.base = f(self.base);
        self
    }

    /// Run the search, keep the best candidate, calibrate and validate it.
    ///
    /// The records are the builder's source: simulated (the chart size
    /// follows from the budget), or read from chart files or raw shards
    /// (its first training records, as many as the budget affords, or the first
    /// [`Budget::Simulations`] of them; no new simulation), calibrated and
    /// validated on the source's held-out records as a preset would be.
    ///
    /// # Errors
    /// An invalid budget, a budget too short for calibration and
    /// validation, too many failed simulations, a chart too small, shards
    /// that hold features, or no candidate that could be fitted.
    pub fn run(self) -> Result<AutoOutcome> {
        let start = Instant::now();
        let AutoDesign {
            base,
            budget,
            compressors,
            networks,
            screening_rows,
        } = self;
        // A simulated chart's size follows from the budget before the run
        // opens it; a chart or shards on disk bring their own, adopted by
        // the run.
        let simulates = base.record_source().simulates();
        let (run, m, deadline, per_simulation) = if simulates {
            base.run_settings().check()?;
            let (m, deadline, per_simulation) = chart_size(
                budget,
                base.simulator(),
                base.run_settings(),
                Sizing::Simulated,
                start,
            )?;
            (base.simulations(m).prepare()?, m, deadline, per_simulation)
        } else {
            let run = base.prepare()?;
            let (m, deadline, per_simulation) =
                chart_size(budget, run.simulator(), run.settings(), Sizing::Read, start)?;
            (run, m, deadline, per_simulation)
        };
        let records = run.records();
        let (mut chart, failures) = records.stored_training()?;
        if !simulates && chart.records.len() > m {
            run.progress().note(&format!(
                "the search fits and scores on the first {m} of the chart's {} training records \
                 (as many as its budget affords; a larger budget uses more)",
                chart.records.len()
            ));
            chart.records.truncate(m);
            chart.thetas = chart.thetas.slice(ndarray::s![..m, ..]).to_owned();
        }
        if chart.records.len() < MIN_SEARCH_RECORDS {
            return Err(Error::InvalidSetting {
                name: "training records",
                value: chart.records.len().to_string(),
                reason: format!(
                    "the automatic design needs at least {MIN_SEARCH_RECORDS} to fit on and \
                     score its candidates: give a larger chart, or hold out fewer records"
                ),
            });
        }
        let (medium, networks) = match networks {
            Some(pair) => pair,
            None => (
                network(&[20])?,
                vec![
                    network(&[10])?,
                    network(&[40])?,
                    network(&[20, 20])?,
                    pieces(4, &[20])?,
                ],
            ),
        };
        let spec = run.simulator().spec();
        let compressors = match compressors {
            Some(list) => list
                .into_iter()
                .filter_map(|c| match c.for_model(spec) {
                    Ok(shaped) => Some(shaped),
                    Err(e) => {
                        run.progress()
                            .note(&format!("the candidate {c} is left out: {e}"));
                        None
                    }
                })
                .collect(),
            None => candidate_compressors(
                spec.output_names().len(),
                spec.input_names().len(),
                spec.n_samples(),
                output_transforms(&chart.records),
            ),
        };
        let scope = Scope::of(&run);
        let mut search = Search::new(
            &scope,
            &chart,
            (budget, deadline),
            screening_rows,
            records.can_grow(),
        );
        run.progress().begin(Stage::Fitting, 0);
        search.round_one(&compressors, &medium);
        search.round_two(&medium, &networks);
        let (seed_scores, half_rows) = search.round_three(search.best(&budget)?);
        let best = search.best(&budget)?;
        let more_pay = half_rows
            .zip(seed_scores.first())
            .is_some_and(|((_, half), own)| more_records_pay(half, *own));
        let rows = search.final_rows(
            best,
            more_pay,
            per_simulation.unwrap_or(f64::INFINITY),
            chart_memory_cap(spec),
        );
        let more = if rows > chart.records.len() {
            let added = rows - chart.records.len();
            run.progress().note(&format!(
                "more records pay: simulating {added} more for the winner's final fit"
            ));
            let more = records.more_training(m, m + added)?;
            // The simulations ended their own stage: the fit goes on.
            run.progress().begin(Stage::Fitting, 0);
            more
        } else {
            None
        };
        let (added_simulations, added_failures) = more
            .as_ref()
            .map_or((0, 0), |(c, failed)| (c.records.len() + failed, *failed));
        let Winner {
            compressor,
            features,
            regressor_config,
            regressor,
            final_fit,
        } = search.winner(best, more.as_ref().map(|(c, _)| c), rows)?;
        run.progress().end(Stage::Fitting);
        let rows_exponent = search.rows_exponent();
        let search_seconds = start.elapsed().as_secs_f64();
        let failures = failures + added_failures;
        let kept = features.nrows();
        let estimator = run.finish(
            compressor,
            regressor,
            TrainedOn {
                features: features.view(),
                simulations: kept + failures,
                failures,
                regressor: regressor_config,
            },
        )?;
        Ok(AutoOutcome {
            estimator,
            candidates: search.reports(),
            best,
            simulations: kept + failures,
            search_seconds,
            failures,
            final_fit,
            seed_scores,
            half_rows,
            added_simulations,
            rows_exponent,
        })
    }
}

/// The most records of `spec`'s model a search keeps in memory.
fn chart_memory_cap(spec: &twostage_models::ModelSpec) -> usize {
    let record_bytes =
        spec.n_samples() * (spec.input_names().len() + spec.output_names().len()) * 8;
    (MAX_CHART_BYTES / record_bytes.max(1)).max(100)
}

/// The number of training records of a search, the deadline of its fits
/// and, for a time budget on simulated records, the pilot's wall seconds
/// per simulation. Simulated: a simulation budget as given; a time budget
/// keeps what calibration and validation will take (timed by a pilot) and
/// spends a fifth of the rest on the chart. Read from files: the first
/// training records, as many as a simulation budget says, or as a time
/// budget would simulate. Either way the records must fit in memory.
fn chart_size<S: Simulator + ?Sized>(
    budget: Budget,
    simulator: &S,
    settings: &RunSettings,
    sizing: Sizing,
    start: Instant,
) -> Result<(usize, Option<Instant>, Option<f64>)> {
    let simulates = sizing == Sizing::Simulated;
    let memory_cap = chart_memory_cap(simulator.spec());
    let mut per_simulation = None;
    let (m, deadline) = match budget {
        Budget::Simulations(m) => (m, None),
        Budget::Seconds(t) => {
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::InvalidSetting {
                    name: "budget seconds",
                    value: t.to_string(),
                    reason: "must be finite and > 0".into(),
                });
            }
            if simulates {
                let pilot = pilot_seconds_per_simulation(simulator, settings.seed_or_default())?;
                per_simulation = Some(pilot);
                let per_simulation = pilot;
                let held_out = settings.calibration + settings.validation;
                // Simulating and compressing the held-out records, with
                // a margin for the intervals' own fits.
                let reserve = 1.2 * per_simulation * held_out as f64 + 1.0;
                if reserve > 0.5 * t {
                    return Err(Error::InvalidSetting {
                        name: "budget seconds",
                        value: format!("{t}"),
                        reason: format!(
                            "calibration and validation alone take about {reserve:.0} s \
                                 ({held_out} simulations): give at least {:.0} s, or fewer \
                                 calibration and validation records",
                            (2.0 * reserve).ceil()
                        ),
                    });
                }
                let search = t - reserve;
                let affordable =
                    (0.2 * search / per_simulation).min(SIMULATIONS_PER_BUDGET_SECOND * search);
                (
                    (affordable as usize).max(500).min(memory_cap),
                    Some(start + Duration::from_secs_f64(search)),
                )
            } else {
                // The fits, not the records, cost the time: a chart gives
                // the search as many records as a simulated search of this
                // budget would chart. The held-out records are compressed
                // once by the winner: a small share of the budget.
                let records = (SIMULATIONS_PER_BUDGET_SECOND * t) as usize;
                (
                    records.max(MIN_SEARCH_RECORDS),
                    Some(start + Duration::from_secs_f64(0.95 * t)),
                )
            }
        }
    };
    if !simulates {
        return Ok((m.min(memory_cap), deadline, None));
    }
    if m < 50 || m > memory_cap {
        return Err(Error::InvalidSetting {
            name: "budget simulations",
            value: m.to_string(),
            reason: format!("must lie in 50..={memory_cap} (the records are kept in memory)"),
        });
    }
    Ok((m, deadline, per_simulation))
}

/// Where a search's training records come from, for its chart size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sizing {
    /// Simulated as the run goes: as many as the budget affords.
    Simulated,
    /// Read from a chart or shards: the first of them.
    Read,
}

/// Streams of the timing pilot, apart from the training chart's.
const PILOT_SEED: u64 = 0x0050_494c_4f54; // "PILOT"

/// Parallel throughput of `simulator` in wall seconds per simulation, from
/// a small timed pilot.
fn pilot_seconds_per_simulation<S: Simulator + ?Sized>(simulator: &S, seed: u64) -> Result<f64> {
    let pilot = 64;
    let design = simulator.prior().design(pilot, seed ^ PILOT_SEED)?;
    let start = Instant::now();
    simulate_records(simulator, &design, pilot, 0.0, None)?;
    Ok((start.elapsed().as_secs_f64() / pilot as f64).max(1e-9))
}

/// Training records a search needs at least: a fifth of them score the
/// candidates.
const MIN_SEARCH_RECORDS: usize = 50;
