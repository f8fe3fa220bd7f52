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

use std::time::{Duration, Instant};

use ndarray::{Array2, Axis};
use rayon::prelude::*;
use twostage_compress::{
    Arx, Compressor, Narx, OutputPca, RawRecord, SignalTransform, Transformed, Workspace,
};
use twostage_fit::{MlpParams, Piecewise};
use twostage_models::{IoData, Simulator};

use crate::builder::{TrainedOn, TwoStage};
use crate::error::{Error, Result};
use crate::estimator::Estimator;
use crate::space::{rows_to_estimates, to_learning_space};
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedRegressor, RegressorConfig};
use twostage_sources::ForModel;
use twostage_sources::Stage;
use twostage_sources::StoredChart;

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
    /// Why it has no score, if it has none (skipped for time, or failed).
    pub note: Option<String>,
    /// How its network was trained (trainer, stop reason, restarts).
    pub trained_by: Option<String>,
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
    /// Seconds of the search (without calibration and validation).
    pub search_seconds: f64,
    /// Whether the winner was refitted on the whole chart (a time budget
    /// may leave room for fewer rows, or only the fit it was scored with).
    pub refitted: bool,
    /// The chart rows the shipped network was fitted on.
    pub fitted_rows: usize,
    /// The round-2 winner's score at the run's seed and, where the budget
    /// allowed, at two other seeds: how much the seed alone moves it.
    pub seed_scores: Vec<f64>,
    /// The round-2 winner fitted on half its rows (how many, and its
    /// score), where the budget allowed: a learning curve's last step,
    /// which says whether more records would pay.
    pub half_rows: Option<(usize, f64)>,
}

impl std::fmt::Display for AutoOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "automatic design on m = {} simulations ({:.1} s), held-out RMSE per candidate:",
            self.simulations, self.search_seconds
        )?;
        if !self.refitted {
            writeln!(
                f,
                "(the time budget left no room to refit the winner on the whole chart: it ships \
                 fitted on {} of its {} records)",
                self.fitted_rows, self.simulations
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
                if half > 1.03 * own {
                    "pay"
                } else {
                    "hardly pay"
                }
            )?;
        }
        for (i, c) in self.candidates.iter().enumerate() {
            let mark = if i == self.best { "*" } else { " " };
            let rmse: Vec<String> = c.rmse.iter().map(|r| format!("{r:.4e}")).collect();
            match &c.note {
                Some(note) => writeln!(f, " {mark} {:<28} {note}", c.design)?,
                None => writeln!(
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
            }
        }
        Ok(())
    }
}

/// Builder of an automatic design for one simulator; see [`TwoStage::auto`].
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
/// Share of the chart held out to score candidates.
const HELD_OUT: f64 = 0.2;
/// Fitting rows round 1 uses at most: it only picks the compressors worth
/// round 2, and the best few are close (on the benchmark at m = 20000 the
/// ARX orders 2 to 4 score within 2% of each other, round 2's networks
/// move the score by 10%); the time saved goes to round 2 on every row.
const SCREENING_ROWS: usize = 4000;
/// How a network's fit time grows with its weights, for round 2's cost
/// estimates (see `round_two`).
const COST_EXPONENT: f64 = 1.2;
/// Memory allowed for the stored records.
const MAX_CHART_BYTES: usize = 2 << 30;

impl<'a, S: Simulator + ?Sized> TwoStage<'a, S> {
    /// An automatic design for `simulator`: the settings of the builder
    /// (seed, calibration, validation, progress...) apply, the compressor,
    /// regressor and m are searched.
    ///
    /// ```
    /// use twostage::{Budget, RegressorConfig, TwoStage};
    /// use twostage::compress::Arx;
    /// use twostage::fit::MlpParams;
    /// use twostage::models::Benchmark;
    ///
    /// let model = Benchmark::builder().n_samples(300).build()?;
    /// let net = |h: usize| -> Result<RegressorConfig, twostage::Error> {
    ///     Ok(RegressorConfig::Mlp(MlpParams::new(&[h])?.restarts(2).check()?))
    /// };
    /// let outcome = TwoStage::auto(&model)
    ///     .budget(Budget::Simulations(400))
    ///     // A small search for the example; the defaults search more.
    ///     .compressors(vec![Arx::new(2, 2)?.into(), Arx::new(4, 4)?.into()])
    ///     .networks(net(6)?, vec![net(3)?])
    ///     .settings(|b| b.calibration(100).validation(100))
    ///     .run()?;
    /// // 2 compressors with one network, the other network on both, then
    /// // the winner's restarts averaged.
    /// assert_eq!(outcome.candidates.len(), 5);
    /// let best = &outcome.candidates[outcome.best];
    /// assert!(outcome.candidates.iter().all(|c| c.note.is_some() || c.score >= best.score));
    /// println!("{outcome}");
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn auto(simulator: &'a S) -> AutoDesign<'a, S> {
        AutoDesign {
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
        let base = base.adopting_source()?;
        base.settings_ref().check()?;
        let simulates = base.record_source().simulates();
        let (m, deadline) = chart_size(budget, &base, simulates, start)?;
        let base = if simulates { base.simulations(m) } else { base };
        let records = base.open_records()?;
        let (mut chart, failures) = records.stored_training()?;
        if !simulates && chart.records.len() > m {
            base.observer().note(&format!(
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
        let spec = base.simulator().spec();
        let compressors = match compressors {
            Some(list) => list
                .into_iter()
                .filter_map(|c| c.for_model(spec).ok())
                .collect(),
            None => candidate_compressors(
                spec.output_names().len(),
                spec.input_names().len(),
                spec.n_samples(),
                output_transforms(&chart.records),
            ),
        };
        let mut search = Search::new(&base, &chart, (budget, deadline), screening_rows);
        base.observer().begin(Stage::Fitting, 0);
        search.round_one(&compressors, &medium);
        search.round_two(&medium, &networks);
        let (seed_scores, half_rows) = search.round_three(search.best(&budget)?);
        let best = search.best(&budget)?;
        let Winner {
            compressor,
            features,
            regressor_config,
            regressor,
            fitted_rows,
        } = search.winner(best)?;
        base.observer().end(Stage::Fitting);
        let search_seconds = start.elapsed().as_secs_f64();
        let kept = chart.records.len();
        let estimator = base.finish(
            compressor,
            regressor,
            TrainedOn {
                features: features.view(),
                simulations: kept + failures,
                failures,
                sampling: records.sampling(),
                regressor: regressor_config,
            },
            &records,
        )?;
        Ok(AutoOutcome {
            estimator,
            candidates: search.candidates,
            best,
            simulations: kept + failures,
            search_seconds,
            refitted: fitted_rows == chart.records.len(),
            fitted_rows,
            seed_scores,
            half_rows,
        })
    }
}

/// The number of training records of a search and the deadline of its
/// fits. Simulated: a simulation budget as given; a time budget keeps what
/// calibration and validation will take (timed by a pilot) and spends a
/// fifth of the rest on the chart. Read from files: the first training
/// records, as many as a simulation budget says, or as a time budget would
/// simulate. Either way the records must fit in memory.
fn chart_size<S: Simulator + ?Sized>(
    budget: Budget,
    base: &TwoStage<'_, S>,
    simulates: bool,
    start: Instant,
) -> Result<(usize, Option<Instant>)> {
    let spec = base.simulator().spec();
    let record_bytes =
        spec.n_samples() * (spec.input_names().len() + spec.output_names().len()) * 8;
    let memory_cap = (MAX_CHART_BYTES / record_bytes.max(1)).max(100);
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
                let per_simulation = base.pilot_seconds_per_simulation()?;
                let held_out = base.settings_ref().calibration + base.settings_ref().validation;
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
        return Ok((m.min(memory_cap), deadline));
    }
    if m < 50 || m > memory_cap {
        return Err(Error::InvalidSetting {
            name: "budget simulations",
            value: m.to_string(),
            reason: format!("must lie in 50..={memory_cap} (the records are kept in memory)"),
        });
    }
    Ok((m, deadline))
}

/// Training records a search needs at least: a fifth of them score the
/// candidates.
const MIN_SEARCH_RECORDS: usize = 50;

/// The candidates of one automatic design: what was tried, on which stored
/// chart, and what each fit gave.
struct Search<'s, 'a, S: Simulator + ?Sized> {
    base: &'s TwoStage<'a, S>,
    chart: &'s StoredChart,
    /// The run's budget (for the progress lines).
    budget: Budget,
    deadline: Option<Instant>,
    /// Round 1's fitting rows at most.
    screening_rows: usize,
    /// Rows of the chart the candidates are fitted on; the rest score them.
    fit_rows: usize,
    /// The prior's standard deviation per parameter: RMSEs are scored in
    /// its units, so that parameters of different scales weigh alike.
    prior_sd: Vec<f64>,
    candidates: Vec<CandidateReport>,
    fitted: Vec<Option<(CompressorConfig, FittedRegressor)>>,
    networks_of: Vec<RegressorConfig>,
}

impl<'s, 'a, S: Simulator + ?Sized> Search<'s, 'a, S> {
    fn new(
        base: &'s TwoStage<'a, S>,
        chart: &'s StoredChart,
        (budget, deadline): (Budget, Option<Instant>),
        screening_rows: usize,
    ) -> Self {
        let prior = base.simulator().spec().prior();
        let prior_sd = prior
            .lower()
            .iter()
            .zip(prior.upper())
            .map(|(lo, hi)| (hi - lo) / 12f64.sqrt())
            .collect();
        let rows = chart.thetas.nrows();
        Self {
            base,
            chart,
            budget,
            deadline,
            screening_rows,
            fit_rows: ((1.0 - HELD_OUT) * rows as f64).round() as usize,
            prior_sd,
            candidates: Vec::new(),
            fitted: Vec::new(),
            networks_of: Vec::new(),
        }
    }

    /// Round 1: every compressor with one medium network. Nothing is known
    /// about costs yet: each starts unless the deadline has passed.
    fn round_one(&mut self, compressors: &[CompressorConfig], medium: &RegressorConfig) {
        let rows = self.fit_rows.min(self.screening_rows);
        let count = compressors.len();
        let outcomes: Vec<_> = compressors
            .par_iter()
            .enumerate()
            .map(|(k, c)| {
                self.tell(1, k, count, c, medium);
                self.evaluate(c, medium, rows, self.deadline.map(|d| (d, 0.0)), 1)
            })
            .collect();
        for (report, outcome) in outcomes {
            self.record(report, outcome, medium.clone());
        }
    }

    /// Round 2: the other networks on the two best compressors (and the
    /// round-1 network again when round 1 only screened a share of the
    /// rows), on every fitting row. Cheapest first, each started only if
    /// its cost (the round-1 time scaled by the network's size and the
    /// rows) leaves time to refit the best candidate found so far.
    fn round_two(&mut self, medium: &RegressorConfig, networks: &[RegressorConfig]) {
        let q = self.chart.thetas.ncols();
        let ranked = self.ranked();
        let screened = self
            .candidates
            .first()
            .map_or(self.fit_rows, |c| c.fit_rows);
        // The refit of the winner on the whole chart, from round 1's best,
        // but at most 45% of the time left: round 2 gets the rest, and the
        // refit takes as many rows as its time affords.
        let all_rows = self.chart.thetas.nrows() as f64;
        let reserve = ranked.first().map_or(0.0, |&i| {
            let refit = refit_seconds(self.candidates[i].seconds, screened, all_rows as usize);
            refit.min(0.45 * self.seconds_left())
        });
        let mut trials: Vec<&RegressorConfig> = Vec::new();
        if screened < self.fit_rows {
            trials.push(medium);
        }
        trials.extend(networks);
        // Each pair's cost on `screened` rows.
        let mut pairs: Vec<(CompressorConfig, RegressorConfig, f64)> = ranked
            .iter()
            .take(2)
            .filter_map(|&i| {
                let (c, _) = self.fitted[i].as_ref()?;
                let n = c.n_features();
                let base_size = network_size(medium, n, q);
                let seconds = self.candidates[i].seconds;
                Some(trials.iter().map(move |net| {
                    // Levenberg-Marquardt's products grow with the square
                    // of the weights, its iterations less: on 16000 rows
                    // the benchmark's fits grew as size^1.4 to size^1.5, on
                    // the 4000 of a screened round as size^0.6 to size^1.1
                    // (other costs weigh more there). Round 2 sizes its rows
                    // by these estimates, so they aim at the middle.
                    let scale = (network_size(net, n, q) / base_size).powf(COST_EXPONENT);
                    (c.clone(), (*net).clone(), seconds * scale)
                }))
            })
            .flatten()
            .collect();
        let rows = self.round_two_rows(&pairs, screened, reserve);
        if rows == screened {
            // Round 1's network on these rows is scored already.
            pairs.retain(|(_, net, _)| net != medium);
        }
        let growth = rows as f64 / screened.max(1) as f64;
        for pair in &mut pairs {
            pair.2 *= growth;
        }
        // Stable: equal costs keep the order above, so a simulation budget
        // (no deadline) evaluates the same list in the same order anywhere.
        pairs.sort_by(|a, b| a.2.total_cmp(&b.2));
        let count = pairs.len();
        let outcomes: Vec<_> = pairs
            .par_iter()
            .enumerate()
            .map(|(k, (c, net, cost))| {
                self.tell(2, k, count, c, net);
                self.evaluate(c, net, rows, self.deadline.map(|d| (d, cost + reserve)), 2)
            })
            .collect();
        for ((report, outcome), (_, net, _)) in outcomes.into_iter().zip(pairs) {
            self.record(report, outcome, net);
        }
    }

    /// The rows round 2 fits on: every fitting row when its candidates
    /// (costs on `screened` rows, growing with the rows) fit in the time
    /// left after the winner's refit (`reserve`) on the cores there are,
    /// else as many as do, but never fewer than round 1 screened. Without a
    /// deadline, every fitting row. Fewer rows for all of round 2 beat
    /// skipping most of its candidates: they compare on equal terms, and
    /// the winner is refitted on the whole chart.
    fn round_two_rows(
        &self,
        pairs: &[(CompressorConfig, RegressorConfig, f64)],
        screened: usize,
        reserve: f64,
    ) -> usize {
        let Some(deadline) = self.deadline else {
            return self.fit_rows;
        };
        let left = deadline
            .saturating_duration_since(Instant::now())
            .as_secs_f64()
            - reserve;
        let costs: f64 = pairs.iter().map(|p| p.2).sum();
        affordable_rows(
            costs / rayon::current_num_threads().max(1) as f64,
            left,
            screened,
            self.fit_rows,
        )
    }

    /// Tell the observer which candidate starts, and how much of the
    /// budget is spent.
    fn tell(
        &self,
        round: usize,
        k: usize,
        count: usize,
        compressor: &CompressorConfig,
        regressor: &RegressorConfig,
    ) {
        // The log line gives the time; the budget says how much there is.
        let budget = match self.budget {
            Budget::Seconds(t) => format!("budget {t:.0} s"),
            Budget::Simulations(_) => "every candidate runs".to_string(),
        };
        self.base.observer().status(&format!(
            "search round {round}, candidate {} of {count}: {}; {budget}",
            k + 1,
            design(compressor, regressor)
        ));
    }

    fn evaluate(
        &self,
        compressor: &CompressorConfig,
        regressor: &RegressorConfig,
        rows: usize,
        limit: Option<(Instant, f64)>,
        round: usize,
    ) -> (CandidateReport, Option<(CompressorConfig, FittedRegressor)>) {
        self.evaluate_seeded(compressor, regressor, rows, limit, (round, 0))
    }

    /// [`Self::evaluate`] with the network's seed moved by `offset` from
    /// the run's.
    fn evaluate_seeded(
        &self,
        compressor: &CompressorConfig,
        regressor: &RegressorConfig,
        rows: usize,
        limit: Option<(Instant, f64)>,
        (round, offset): (usize, u64),
    ) -> (CandidateReport, Option<(CompressorConfig, FittedRegressor)>) {
        evaluate(
            self.base,
            self.chart,
            (compressor, regressor),
            (rows, self.fit_rows),
            &self.prior_sd,
            limit,
            (round, self.base.seed_value().wrapping_add(offset)),
        )
    }

    /// Round 3, where the budget allows: the winner's network with its
    /// restarts averaged (an ensemble of independently seeded networks,
    /// which competes), and the winner at two other seeds (which does not:
    /// picking the luckiest seed would fit the held-out rows; it says how
    /// much the seed matters), and the winner on half its rows (does more
    /// data pay?). Returns the winner's scores at its own and the other
    /// seeds, and its rows and score on half the rows.
    fn round_three(&mut self, best: usize) -> (Vec<f64>, Option<(usize, f64)>) {
        let Some((compressor, _)) = self.fitted[best].clone() else {
            return (Vec::new(), None);
        };
        let network = self.networks_of[best].clone();
        let winner = &self.candidates[best];
        let rows = winner.fit_rows;
        // Each trial, and the winner's refit on the whole chart after it,
        // must end in time.
        let refit = refit_seconds(winner.seconds, rows, self.chart.thetas.nrows())
            .min(0.45 * self.seconds_left());
        let limit = self.deadline.map(|d| (d, 1.25 * winner.seconds + refit));
        // (network, seed offset, whether it competes, rows)
        let mut trials: Vec<(RegressorConfig, u64, bool, usize)> = vec![
            (network.clone(), 1, false, rows),
            (network.clone(), 2, false, rows),
            (network.clone(), 0, false, rows / 2),
        ];
        if let RegressorConfig::Mlp(mlp) = &network
            && !mlp.params().is_ensemble()
            && let Ok(averaged) = mlp.params().clone().ensemble(true).check()
        {
            trials.insert(0, (RegressorConfig::Mlp(averaged), 0, true, rows));
        }
        let count = trials.len();
        let outcomes: Vec<_> = trials
            .par_iter()
            .enumerate()
            .map(|(k, (net, offset, _, rows))| {
                self.tell(3, k, count, &compressor, net);
                self.evaluate_seeded(&compressor, net, *rows, limit, (3, *offset))
            })
            .collect();
        let mut scores = vec![self.candidates[best].score];
        let mut half = None;
        for ((report, outcome), (net, _, competes, trial_rows)) in outcomes.into_iter().zip(trials)
        {
            if competes {
                self.record(report, outcome, net);
            } else if report.note.is_some() {
                // Skipped for time: nothing to say.
            } else if trial_rows < rows {
                half = Some((trial_rows, report.score));
            } else {
                scores.push(report.score);
            }
        }
        (scores, half)
    }

    fn record(
        &mut self,
        report: CandidateReport,
        outcome: Option<(CompressorConfig, FittedRegressor)>,
        network: RegressorConfig,
    ) {
        self.candidates.push(report);
        self.fitted.push(outcome);
        self.networks_of.push(network);
    }

    /// The candidates that were fitted, best score first (ties keep the
    /// order in which they were tried).
    fn ranked(&self) -> Vec<usize> {
        let mut ranked: Vec<usize> = (0..self.candidates.len())
            .filter(|&i| self.candidates[i].note.is_none())
            .collect();
        ranked.sort_by(|&a, &b| {
            self.candidates[a]
                .score
                .total_cmp(&self.candidates[b].score)
        });
        ranked
    }

    /// The best candidate's index: among those fitted on the most rows
    /// (round 2's and 3's; a screened round-1 fit is not compared with
    /// them), or, if round 1 alone was fitted, among all.
    fn best(&self, budget: &Budget) -> Result<usize> {
        let fitted = |i: &usize| self.candidates[*i].note.is_none();
        let most_rows = (0..self.candidates.len())
            .filter(fitted)
            .map(|i| self.candidates[i].fit_rows)
            .max();
        (0..self.candidates.len())
            .filter(|i| fitted(i) && Some(self.candidates[*i].fit_rows) == most_rows)
            .min_by(|&a, &b| {
                self.candidates[a]
                    .score
                    .total_cmp(&self.candidates[b].score)
            })
            .ok_or_else(|| Error::InvalidSetting {
                name: "budget",
                value: format!("{budget:?}"),
                reason: format!(
                    "no candidate could be fitted within it (first: {})",
                    self.candidates
                        .first()
                        .and_then(|c| c.note.clone())
                        .unwrap_or_default()
                ),
            })
    }

    /// Seconds until the deadline (infinite without one).
    fn seconds_left(&self) -> f64 {
        self.deadline.map_or(f64::INFINITY, |d| {
            d.saturating_duration_since(Instant::now()).as_secs_f64()
        })
    }

    /// The winner, refitted on the whole chart, or on as many of its first
    /// rows as the time left affords; with the fit it was scored with when
    /// that is not more rows.
    fn winner(&self, best: usize) -> Result<Winner> {
        let (compressor, held_out_fit) =
            self.fitted[best]
                .clone()
                .ok_or_else(|| Error::InvalidSetting {
                    name: "budget",
                    value: String::new(),
                    reason: "the best candidate lost its fit".into(),
                })?;
        let regressor_config = self.networks_of[best].clone();
        let scored_rows = self.candidates[best].fit_rows;
        let all_rows = self.chart.thetas.nrows();
        let refit_rows = match self.deadline {
            None => all_rows,
            Some(_) => affordable_rows(
                refit_seconds(self.candidates[best].seconds, scored_rows, scored_rows),
                self.seconds_left(),
                scored_rows,
                all_rows,
            ),
        };
        let features = compress_all(&compressor, &self.chart.records)?;
        let (regressor, fitted_rows) = if refit_rows > scored_rows {
            let marginals = self.base.simulator().spec().prior().marginals();
            let rows = ndarray::s![..refit_rows, ..];
            let fitted = regressor_config.fit(
                features.slice(rows),
                to_learning_space(self.chart.thetas.slice(rows), marginals).view(),
                self.base.seed_value(),
            )?;
            (fitted, refit_rows)
        } else {
            (held_out_fit, scored_rows)
        };
        Ok(Winner {
            compressor,
            features,
            regressor_config,
            regressor,
            fitted_rows,
        })
    }
}

/// The seconds a refit on `rows` rows takes, from a candidate's `seconds`
/// on `scored` rows: with a margin of a quarter, growing with the rows, and
/// on the whole machine, where the candidate shared it with the others of
/// its round (each round runs at least as many candidates as threads).
fn refit_seconds(seconds: f64, scored: usize, rows: usize) -> f64 {
    1.25 * seconds * rows as f64 / scored.max(1) as f64 / rayon::current_num_threads().max(1) as f64
}

/// Rows a round can fit on in `left` seconds when it costs `seconds` of
/// wall time on `screened` rows and grows linearly with them: all `rows`
/// if they fit, else as many as 80% of the time affords (the costs are
/// estimates), but never fewer than `screened`.
fn affordable_rows(seconds: f64, left: f64, screened: usize, rows: usize) -> usize {
    let per_row = seconds / screened.max(1) as f64;
    if per_row.is_nan() || per_row <= 0.0 {
        return rows;
    }
    let affordable = (0.8 * left / per_row).max(0.0) as usize;
    affordable.clamp(screened.min(rows), rows)
}

/// What the search ships: the winning structure, fitted.
struct Winner {
    compressor: CompressorConfig,
    /// The whole chart's features under the winning compressor.
    features: Array2<f64>,
    regressor_config: RegressorConfig,
    regressor: FittedRegressor,
    /// The chart rows the shipped network was fitted on.
    fitted_rows: usize,
}

/// Both stages as the command line writes them, for reports and progress.
fn design(compressor: &CompressorConfig, regressor: &RegressorConfig) -> String {
    format!(
        "{} {}",
        compressor.spec().unwrap_or_else(|| compressor.to_string()),
        regressor.spec().unwrap_or_else(|| regressor.to_string())
    )
}

/// Weights and biases of a network candidate on n features and q outputs:
/// the cost of a Levenberg-Marquardt fit grows with its power
/// [`COST_EXPONENT`] or so (round 2).
fn network_size(regressor: &RegressorConfig, n: usize, q: usize) -> f64 {
    match regressor {
        RegressorConfig::Mlp(mlp) => {
            let mut sizes = vec![n];
            sizes.extend_from_slice(mlp.params().hidden());
            sizes.push(q);
            twostage_fit::n_parameters(&sizes) as f64
        }
        // The global network on every row, then experts that together see
        // the rows about 1.5 times (their margins overlap).
        RegressorConfig::Piecewise(p) => {
            2.5 * network_size(&RegressorConfig::Mlp(p.global().clone()), n, q)
        }
        _ => (n * q + q) as f64,
    }
}

fn pieces(count: usize, hidden: &[usize]) -> Result<RegressorConfig> {
    let mlp = MlpParams::new(hidden)?.check()?;
    Ok(RegressorConfig::Piecewise(Piecewise::new(
        mlp.clone(),
        mlp,
        count,
    )?))
}

fn network(hidden: &[usize]) -> Result<RegressorConfig> {
    Ok(RegressorConfig::Mlp(MlpParams::new(hidden)?.check()?))
}

/// Stage-1 candidates that fit the records' shape: ARX orders (AR on the
/// outputs for a model without input), a quadratic NARX for one input and
/// one output, output PCAs, and the raw record when it has at most
/// [`RAW_CANDIDATE_VALUES`] values. A least-squares structure is left out
/// when its coefficients would be more than a quarter of the samples.
/// Unfitted compressors (NARX scales, PCA directions) are fitted on the
/// chart's fitting rows before use.
///
/// With `transforms`, every structure is tried a second time on the
/// transformed outputs: the held-out risk, not a rule, decides whether
/// logarithms pay.
fn candidate_compressors(
    n_outputs: usize,
    n_inputs: usize,
    n_samples: usize,
    transforms: Option<Vec<SignalTransform>>,
) -> Vec<CompressorConfig> {
    let fits = |coefficients: usize| 4 * coefficients <= n_samples;
    let mut list: Vec<CompressorConfig> = Vec::new();
    for order in [2, 3, 4, 5, 6, 8] {
        let input_lags = if n_inputs == 0 { 0 } else { order };
        if let Ok(arx) =
            Arx::new(order, input_lags).and_then(|a| a.with_signals(n_inputs, n_outputs))
            && fits(order * n_outputs + input_lags * n_inputs)
        {
            list.push(arx.into());
        }
    }
    if (n_inputs, n_outputs) == (1, 1)
        && let Ok(narx) = Narx::new(2, 2, 2)
        && fits(narx.n_features())
    {
        list.push(narx.into());
    }
    for k in [8, 12, 16] {
        if let Ok(pca) = OutputPca::new(k)
            && k < n_samples * n_outputs
        {
            list.push(pca.into());
        }
    }
    let values = n_samples * (n_inputs + n_outputs);
    if values <= RAW_CANDIDATE_VALUES
        && let Ok(raw) = RawRecord::new(n_samples, n_inputs, n_outputs)
    {
        list.push(CompressorConfig::Raw(raw));
    }
    if let Some(transforms) = transforms {
        let transformed: Vec<CompressorConfig> = list
            .iter()
            .filter_map(|c| Transformed::new(transforms.clone(), c.clone()).ok())
            .map(CompressorConfig::Transformed)
            .collect();
        list.extend(transformed);
    }
    list
}

/// The transform a careful human would try on each output, judged from
/// the training records: the logarithm where an output is always
/// positive, `ln(1 + y)` where it is never negative but reaches zero (a
/// count), none where it goes negative; `None` when no output would be
/// transformed. Only the outputs that span more than a decade are
/// transformed: on a narrow range the logarithm is nearly linear and
/// changes nothing a network cannot absorb.
fn output_transforms(records: &[IoData]) -> Option<Vec<SignalTransform>> {
    let n_outputs = records.first()?.n_outputs();
    let transforms: Vec<SignalTransform> = (0..n_outputs)
        .map(|j| {
            let (mut low, mut high, mut low_positive) = (f64::INFINITY, 0.0f64, f64::INFINITY);
            for record in records {
                for &v in record.output(j) {
                    low = low.min(v);
                    high = high.max(v);
                    if v > 0.0 {
                        low_positive = low_positive.min(v);
                    }
                }
            }
            let spans_decades = high > 10.0 * low_positive;
            match () {
                _ if !spans_decades || !low.is_finite() => SignalTransform::Identity,
                _ if low > 0.0 => SignalTransform::Log,
                _ if low == 0.0 => SignalTransform::Log1p,
                _ => SignalTransform::Identity,
            }
        })
        .collect();
    transforms
        .iter()
        .any(|t| *t != SignalTransform::Identity)
        .then_some(transforms)
}

/// The longest record (in values) whose raw samples the search tries as
/// features.
const RAW_CANDIDATE_VALUES: usize = 256;

/// Features of every record, in parallel (row i is record i).
fn compress_all(compressor: &CompressorConfig, records: &[IoData]) -> Result<Array2<f64>> {
    let n = compressor.n_features();
    let mut features = vec![0.0; records.len() * n];
    features
        .par_chunks_mut(n.max(1))
        .zip(records.par_iter())
        .map_init(Workspace::new, |work, (alpha, record)| {
            compressor.compress_into(record.inputs(), record.outputs(), work, alpha)
        })
        .collect::<twostage_compress::Result<Vec<()>>>()?;
    Ok(Array2::from_shape_vec((records.len(), n), features)
        .unwrap_or_else(|_| unreachable!("n features per record")))
}

/// Compress, fit on the first `rows` rows, score on the rows from
/// `held_out` on (`rows <= held_out`).
fn evaluate<S: Simulator + ?Sized>(
    base: &TwoStage<'_, S>,
    chart: &StoredChart,
    (compressor, regressor): (&CompressorConfig, &RegressorConfig),
    (fit_rows, held_out): (usize, usize),
    prior_sd: &[f64],
    deadline: Option<(Instant, f64)>,
    (round, seed): (usize, u64),
) -> (CandidateReport, Option<(CompressorConfig, FittedRegressor)>) {
    let mut report = CandidateReport {
        compressor: compressor.to_string(),
        regressor: regressor.to_string(),
        design: design(compressor, regressor),
        trained_by: None,
        round,
        rmse: Vec::new(),
        score: f64::INFINITY,
        seconds: 0.0,
        fit_rows,
        note: None,
    };
    // (deadline, estimated seconds): skip what would not finish in time.
    if let Some((deadline, cost)) = deadline
        && Instant::now() + Duration::from_secs_f64(cost) > deadline
    {
        report.note = Some(format!(
            "skipped: about {cost:.0} s would overrun the time budget"
        ));
        return (report, None);
    }
    let start = Instant::now();
    // A structure the records cannot take (an autoregression of a
    // noise-free decay is rank deficient) does not apply; only a fit that
    // went wrong failed.
    let compressed = compressor
        .prepared_on(&chart.records[..fit_rows])
        .map_err(Error::from)
        .and_then(|c| compress_all(&c, &chart.records).map(|f| (c, f)));
    let (compressor, features) = match compressed {
        Ok(pair) => pair,
        Err(e) => {
            report.seconds = start.elapsed().as_secs_f64();
            report.note = Some(format!("does not apply to these records: {e}"));
            return (report, None);
        }
    };
    let outcome = (|| -> Result<(Vec<f64>, CompressorConfig, FittedRegressor)> {
        let (x_fit, x_held) = features.view().split_at(Axis(0), held_out);
        let (t_fit, t_held) = chart.thetas.view().split_at(Axis(0), held_out);
        let (x_fit, t_fit) = (
            x_fit.slice_move(ndarray::s![..fit_rows, ..]),
            t_fit.slice_move(ndarray::s![..fit_rows, ..]),
        );
        let prior = base.simulator().spec().prior();
        let z_fit = to_learning_space(t_fit, prior.marginals());
        let fitted = regressor.fit(x_fit, z_fit.view(), seed)?;
        let mut estimates = twostage_fit::Predictor::predict(&fitted, x_held)?;
        rows_to_estimates(
            &mut estimates,
            prior.marginals(),
            prior.lower(),
            prior.upper(),
        );
        let rmse = (0..t_held.ncols())
            .map(|j| {
                let sq: f64 = t_held
                    .column(j)
                    .iter()
                    .zip(estimates.column(j))
                    .map(|(t, e)| (t - e).powi(2))
                    .sum();
                (sq / t_held.nrows().max(1) as f64).sqrt()
            })
            .collect();
        Ok((rmse, compressor.clone(), fitted))
    })();
    report.seconds = start.elapsed().as_secs_f64();
    match outcome {
        Ok((rmse, compressor, fitted)) => {
            report.trained_by = fitted.training_summary();
            report.score = rmse.iter().zip(prior_sd).map(|(r, sd)| r / sd).sum::<f64>()
                / rmse.len().max(1) as f64;
            report.rmse = rmse;
            (report, Some((compressor, fitted)))
        }
        Err(e) => {
            report.note = Some(format!("failed: {e}"));
            (report, None)
        }
    }
}

#[cfg(test)]
mod shape_tests {
    use super::*;

    fn names(list: &[CompressorConfig]) -> Vec<String> {
        list.iter().map(ToString::to_string).collect()
    }

    /// Round 2 fits every row when it can, as many as the time affords when
    /// it cannot, and never fewer than round 1 screened.
    #[test]
    fn round_two_takes_the_rows_its_time_affords() {
        // 100 s on 4000 rows: 32000 rows would take 800 s.
        assert_eq!(affordable_rows(100.0, 1000.0, 4000, 32000), 32000);
        assert_eq!(affordable_rows(100.0, 500.0, 4000, 32000), 16000);
        assert_eq!(affordable_rows(100.0, 10.0, 4000, 32000), 4000);
        assert_eq!(affordable_rows(100.0, -5.0, 4000, 32000), 4000);
        // Round 1 fitted every row already: nothing more to take.
        assert_eq!(affordable_rows(100.0, 10.0, 240, 240), 240);
        assert_eq!(affordable_rows(0.0, 10.0, 4000, 32000), 32000);
    }

    /// The built-in models' search is what it was; a short record without
    /// input gets autoregressions and its raw samples, nothing that cannot
    /// run on it.
    #[test]
    fn the_candidates_fit_the_records_shape() {
        let siso = candidate_compressors(1, 1, 1000, None);
        assert_eq!(siso.len(), 6 + 1 + 3);
        assert!(siso.iter().all(|c| !matches!(c, CompressorConfig::Raw(_))));
        let short = candidate_compressors(1, 0, 10, None);
        let shown = names(&short);
        assert!(
            short.iter().all(|c| c.n_features() * 4 <= 10
                || matches!(c, CompressorConfig::Raw(_) | CompressorConfig::Pca(_))),
            "{shown:?}"
        );
        assert!(
            matches!(short.last(), Some(CompressorConfig::Raw(r)) if r.n_samples() == 10),
            "{shown:?}"
        );
        assert!(!shown.iter().any(|s| s.contains("NARX")), "{shown:?}");
        // Two outputs, no input, a long record: ARs, PCAs, no raw.
        let mimo = candidate_compressors(2, 0, 400, None);
        assert!(
            mimo.iter()
                .any(|c| matches!(c, CompressorConfig::Arx(a) if a.nb() == 0))
        );
        assert!(
            mimo.iter()
                .all(|c| !matches!(c, CompressorConfig::Raw(_) | CompressorConfig::Narx(_)))
        );
    }
}
