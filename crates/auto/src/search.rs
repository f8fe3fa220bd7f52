//! One automatic design's candidates: its three rounds on a stored chart,
//! what each costs and scores, and the winner it ships.

use std::time::{Duration, Instant};

use ndarray::Axis;
use rayon::prelude::*;
use twostage_compress::{Compressor, CompressorConfig};
use twostage_fit::{FittedRegressor, RegressorConfig};
use twostage_models::Simulator;
use twostage_sources::{ForModel, StoredChart};

use crate::candidates::{design, fit_cost, with_level, with_summary};

mod anytime;
mod equal_time;
mod features;
mod final_fit;
mod learned;

use features::{compress_all, readable_rows};

use crate::cost::{
    COST_MARGIN, LEARNED_SHARE, MIN_TIE, PRODUCTS_EXPONENT, REFIT_SHARE, SIZED_SHARE,
    affordable_rows, fit_seconds, measured_exponent, round_two_floor, rows_growth, screening_rows,
};
use crate::{Budget, CandidateReport, Status};
pub(super) use final_fit::Winner;
use twostage_estimator::space::{rows_to_estimates, to_learning_space};
use twostage_sources::Progress;
use twostage_train::{Error, Result};

/// Share of the chart held out to score candidates.
const HELD_OUT: f64 = 0.2;
/// What the search reads of its run, shared by its parallel fits (the
/// run's records, a cache, are not).
pub(crate) struct Scope<'a, S: ?Sized> {
    simulator: &'a S,
    seed: u64,
    progress: &'a dyn Progress,
    /// Calibration and validation records of the run.
    held_out: usize,
    /// Share of records a stage 1 may fail to compress (as the run's
    /// simulations may fail): they are left out of its fit and score.
    max_failure_fraction: f64,
}

impl<'a, S: Simulator + ?Sized> Scope<'a, S> {
    /// The scope of `run`.
    pub(crate) fn of(run: &twostage_train::Run<'a, S>) -> Self {
        Self {
            simulator: run.simulator(),
            seed: run.seed(),
            progress: run.progress(),
            held_out: run.settings().calibration + run.settings().validation,
            max_failure_fraction: run.settings().max_failure_fraction,
        }
    }

    fn simulator(&self) -> &'a S {
        self.simulator
    }

    fn seed(&self) -> u64 {
        self.seed
    }

    fn progress(&self) -> &'a dyn Progress {
        self.progress
    }
}

/// What a search is given and never changes while its rounds run: its
/// run, its chart, its budget and the rows it fits and scores on. The
/// rounds read it in parallel; their results live in [`Search`].
pub(super) struct Plan<'s, 'a, S: Simulator + ?Sized> {
    base: &'s Scope<'a, S>,
    chart: &'s StoredChart,
    /// The run's budget (for the progress lines).
    budget: Budget,
    deadline: Option<Instant>,
    /// The end of a time budget: the search's deadline keeps what comes
    /// after it before this.
    budget_end: Option<Instant>,
    /// Round 1's fitting rows, and the full screening rows round 2 goes
    /// back to where round 1 was cheap (see [`screening_rows`]).
    screening_rows: usize,
    full_screening_rows: usize,
    /// Rows of the chart the candidates are fitted on; the rest score them.
    fit_rows: usize,
    /// The prior's standard deviation per parameter: RMSEs are scored in
    /// its units, so that parameters of different scales weigh alike.
    prior_sd: Vec<f64>,
    /// Whether the source can simulate more records for the winner's final
    /// fit (a time budget on a growable source): round 2 then keeps time
    /// for it.
    grows: bool,
}

/// The candidates of one automatic design: what was tried under its
/// [`Plan`], and what each fit gave.
pub(super) struct Search<'s, 'a, S: Simulator + ?Sized> {
    plan: Plan<'s, 'a, S>,
    /// Every candidate, in the order tried.
    candidates: Vec<Candidate>,
    /// How the round-2 winner's fit time grew from half its rows to all of
    /// them, both timed alone in round 3: the exponent of its cost in the
    /// rows, where measured.
    rows_exponent: Option<f64>,
    /// How much the seed alone moved the round-2 winner's score in round 3
    /// (the spread of its scores at three seeds over the best), where
    /// measured.
    seed_spread: Option<f64>,
    /// Round 1's wall seconds, and the seconds the search had left when it
    /// started, where it ran under a deadline.
    round_one_time: Option<(f64, f64)>,
    /// Round 3's averaged network and the round-2 winner it averages (both
    /// indices), where it was scored.
    averaged_twin: Option<(usize, usize)>,
    /// The round-2 winner's rows and score on half its rows, where round 3
    /// measured them.
    half_rows: Option<(usize, f64)>,
}

/// One candidate of a search: its report, its network as configured, its
/// fit where it was scored, and its fit's time alone where measured.
struct Candidate {
    report: CandidateReport,
    network: RegressorConfig,
    /// The prepared stage 1 and the fitted stage 2, where it was scored.
    fitted: Option<(CompressorConfig, FittedRegressor)>,
    /// Its fit's seconds with the machine to itself, where known (round 3
    /// runs alone; the round-2 winner's seed trials time it): a refit's
    /// cost follows from these far better than from a round's shared time.
    solo_seconds: Option<f64>,
}

/// What a round-3 trial is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TrialRole {
    /// The winner on half its rows: does more data pay?
    HalfRows,
    /// Another structure built from the winner, which competes.
    Rival,
    /// The winner's restarts averaged: a rival that competes with the
    /// winner at equal final-fit time too ([`Search::equal_time`]).
    Averaged,
    /// The winner at another seed: how much the seed alone moves it.
    OtherSeed,
}

/// A round-3 trial: a structure, its network's seed offset from the run's,
/// its rows, and what it is for.
struct Trial {
    compressor: CompressorConfig,
    network: RegressorConfig,
    seed_offset: u64,
    rows: usize,
    role: TrialRole,
}

impl<'s, 'a, S: Simulator + ?Sized> Search<'s, 'a, S> {
    pub(super) fn new(
        base: &'s Scope<'a, S>,
        chart: &'s StoredChart,
        (budget, start, deadline): (Budget, Instant, Option<Instant>),
        asked_screening_rows: Option<usize>,
        grows: bool,
    ) -> Self {
        let prior = base.simulator().spec().prior();
        let prior_sd = prior
            .lower()
            .iter()
            .zip(prior.upper())
            .map(|(lo, hi)| (hi - lo) / 12f64.sqrt())
            .collect();
        let rows = chart.thetas.nrows();
        let fit_rows = ((1.0 - HELD_OUT) * rows as f64).round() as usize;
        let grows = grows && deadline.is_some();
        let (full_screening_rows, screening_rows) =
            screening_rows(asked_screening_rows, fit_rows, grows);
        Self {
            plan: Plan {
                base,
                chart,
                budget,
                deadline,
                budget_end: match budget {
                    Budget::Seconds(t) => Some(start + Duration::from_secs_f64(t.max(0.0))),
                    Budget::Simulations(_) => None,
                },
                screening_rows,
                full_screening_rows,
                fit_rows,
                prior_sd,
                grows,
            },
            candidates: Vec::new(),
            rows_exponent: None,
            seed_spread: None,
            round_one_time: None,
            averaged_twin: None,
            half_rows: None,
        }
    }

    /// Round 1: every compressor with one medium network. Nothing is known
    /// about costs yet: each starts unless the deadline has passed.
    pub(super) fn round_one(&mut self, compressors: &[CompressorConfig], medium: &RegressorConfig) {
        let rows = self.plan.screening_rows;
        let (started, left) = (Instant::now(), self.plan.seconds_left());
        let count = compressors.len();
        let outcomes: Vec<_> = compressors
            .par_iter()
            .enumerate()
            .map(|(k, c)| {
                self.plan.tell(1, k, count, c, medium);
                self.plan
                    .evaluate(c, medium, rows, self.plan.deadline.map(|d| (d, 0.0)), 1, 0)
            })
            .collect();
        for (report, outcome) in outcomes {
            self.record(report, outcome, medium.clone());
        }
        if self.plan.deadline.is_some() {
            self.round_one_time = Some((started.elapsed().as_secs_f64(), left));
        }
    }

    /// Round 2: the other networks on the two best compressors (and the
    /// round-1 network again when round 1 only screened a share of the
    /// rows), on as many fitting rows as the time affords, never fewer than
    /// round 1 fitted, and at least the full screening rows where round 1
    /// proved cheap. Cheapest first, each started only if
    /// its cost (the round-1 time scaled by the network's size and the
    /// rows) leaves time to refit the best candidate found so far.
    pub(super) fn round_two(&mut self, medium: &RegressorConfig, networks: &[RegressorConfig]) {
        let q = self.plan.chart.thetas.ncols();
        let ranked = self.ranked();
        let screened = self
            .candidates
            .first()
            .map_or(self.plan.fit_rows, |c| c.report.fit_rows);
        // The refit of the winner on the whole chart, from round 1's best,
        // but at most 45% of the time left: round 2 gets the rest, and the
        // refit takes as many rows as its time affords. A source that can
        // simulate more keeps the 45% for a final fit on more records:
        // where its learning curve still falls, rows pay more than a
        // finer comparison of networks.
        let all_rows = self.plan.chart.thetas.nrows() as f64;
        let reserve = ranked.first().map_or(0.0, |&i| {
            let refit = fit_seconds(
                self.candidates[i].report.seconds,
                screened,
                all_rows as usize,
            );
            let share = REFIT_SHARE * self.plan.seconds_left();
            if self.plan.grows {
                share
            } else if self.sized_network_competes(i) {
                SIZED_SHARE * self.plan.seconds_left()
            } else {
                refit.min(share)
            }
        });
        let mut trials: Vec<&RegressorConfig> = Vec::new();
        if screened < self.plan.fit_rows {
            trials.push(medium);
        }
        trials.extend(networks);
        // Each pair's cost on `screened` rows.
        let mut pairs: Vec<(CompressorConfig, RegressorConfig, f64)> = ranked
            .iter()
            .take(2)
            .filter_map(|&i| {
                let (c, _) = self.candidates[i].fitted.as_ref()?;
                let n = c.n_features();
                let base_cost = fit_cost(medium, n, q);
                let seconds = self.candidates[i].report.seconds;
                Some(trials.iter().map(move |net| {
                    // Levenberg-Marquardt's products dominate its time, its
                    // iterations grow less, and other costs weigh more on a
                    // screened round's rows. Round 2 sizes its rows by these
                    // estimates, so they aim at the middle of what was
                    // measured.
                    let scale = (fit_cost(net, n, q) / base_cost).powf(PRODUCTS_EXPONENT);
                    (c.clone(), (*net).clone(), seconds * scale)
                }))
            })
            .flatten()
            .collect();
        let floor = self.round_one_time.map_or(screened, |(seconds, left)| {
            round_two_floor((screened, seconds), self.plan.full_screening_rows, left)
        });
        let rows = self
            .plan
            .round_two_rows(&pairs, screened, reserve)
            .max(floor)
            .min(self.plan.fit_rows);
        if rows == screened {
            // Round 1's network on these rows is scored already.
            pairs.retain(|(_, net, _)| net != medium);
        }
        let growth = rows_growth(screened, rows);
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
                self.plan.tell(2, k, count, c, net);
                self.plan.evaluate(
                    c,
                    net,
                    rows,
                    self.plan.deadline.map(|d| (d, cost + reserve)),
                    2,
                    0,
                )
            })
            .collect();
        for ((report, outcome), (_, net, _)) in outcomes.into_iter().zip(pairs) {
            self.record(report, outcome, net);
        }
    }

    /// Round 3, where the budget allows: the winner's network with its
    /// restarts averaged (an ensemble of independently seeded networks,
    /// which competes), and the winner at two other seeds (which does not:
    /// picking the luckiest seed would fit the held-out rows; it says how
    /// much the seed matters), and the winner on half its rows (does more
    /// data pay? kept for [`Self::half_rows`]). Returns the winner's
    /// scores at its own and the other seeds.
    pub(super) fn round_three(&mut self, best: usize) -> Vec<f64> {
        let Some((compressor, _)) = self.candidates[best].fitted.clone() else {
            return Vec::new();
        };
        let network = self.candidates[best].network.clone();
        let winner = &self.candidates[best].report;
        let rows = winner.fit_rows;
        // Each trial, and the winner's refit on the whole chart after it,
        // must end in time.
        let refit = if self.sized_network_competes(best) {
            SIZED_SHARE * self.plan.seconds_left()
        } else {
            fit_seconds(winner.seconds, rows, self.plan.chart.thetas.nrows())
                .min(REFIT_SHARE * self.plan.seconds_left())
        };
        let limit = self
            .plan
            .deadline
            .map(|d| (d, COST_MARGIN * winner.seconds + refit));
        let trial = |compressor: &CompressorConfig, network: &RegressorConfig, role, rows| Trial {
            compressor: compressor.clone(),
            network: network.clone(),
            seed_offset: 0,
            rows,
            role,
        };
        // The half-rows trial first: the cheapest, and the one that decides
        // whether the final fit takes more records.
        let mut trials = vec![trial(&compressor, &network, TrialRole::HalfRows, rows / 2)];
        let n_outputs = self.plan.base.simulator().spec().output_names().len();
        if let Some(leveled) = with_level(&compressor, n_outputs) {
            trials.push(trial(&leveled, &network, TrialRole::Rival, rows));
        }
        if let Some(summarized) = with_summary(&compressor, &self.plan.chart.records[..rows]) {
            trials.push(trial(&summarized, &network, TrialRole::Rival, rows));
        }
        if let RegressorConfig::Mlp(mlp) = &network
            && !mlp.params().is_ensemble()
            && let Ok(averaged) = mlp.params().clone().ensemble(true).check()
        {
            let averaged = RegressorConfig::Mlp(averaged);
            trials.push(trial(&compressor, &averaged, TrialRole::Averaged, rows));
        }
        for seed_offset in [1, 2] {
            trials.push(Trial {
                seed_offset,
                ..trial(&compressor, &network, TrialRole::OtherSeed, rows)
            });
        }
        // One after the other, each on the whole machine (its restarts and
        // products run in parallel): their times are then what the final
        // fit's cost is estimated from.
        let count = trials.len();
        let outcomes: Vec<_> = trials
            .iter()
            .enumerate()
            .map(|(k, t)| {
                self.plan.tell(3, k, count, &t.compressor, &t.network);
                self.plan
                    .evaluate(&t.compressor, &t.network, t.rows, limit, 3, t.seed_offset)
            })
            .collect();
        let mut scores = vec![self.candidates[best].report.score];
        let first_rival = self.candidates.len();
        let mut seed_seconds = Vec::new();
        let (mut half, mut half_seconds) = (None, None);
        for ((report, outcome), trial) in outcomes.into_iter().zip(trials) {
            let scored = report.status.is_scored();
            match trial.role {
                TrialRole::Rival | TrialRole::Averaged => {
                    self.record_timed_alone(report, outcome, trial.network);
                    if scored && trial.role == TrialRole::Averaged {
                        self.averaged_twin = Some((best, self.candidates.len() - 1));
                    }
                }
                // Skipped for time: nothing to say.
                _ if !scored => {}
                TrialRole::HalfRows => {
                    half = Some((trial.rows, report.score));
                    half_seconds = Some(report.seconds);
                }
                TrialRole::OtherSeed => {
                    scores.push(report.score);
                    seed_seconds.push(report.seconds);
                }
            }
        }
        self.learned_rival(best, first_rival, rows, limit);
        if scores.len() > 1 {
            let (lo, hi) = scores
                .iter()
                .fold((f64::INFINITY, 0f64), |(lo, hi), &s| (lo.min(s), hi.max(s)));
            self.seed_spread = Some((hi - lo) / lo);
        }
        self.half_rows = half;
        if !seed_seconds.is_empty() {
            let seconds = seed_seconds.iter().sum::<f64>() / seed_seconds.len() as f64;
            self.candidates[best].solo_seconds = Some(seconds);
            self.rows_exponent = half_seconds
                .zip(half)
                .map(|(t, (r, _))| measured_exponent((r, t), (rows, seconds)));
        }
        scores
    }

    /// [`Self::record`] of a fit that ran alone on the machine: its time
    /// is its own, what the final fit's cost is estimated from.
    fn record_timed_alone(
        &mut self,
        report: CandidateReport,
        fitted: Option<(CompressorConfig, FittedRegressor)>,
        network: RegressorConfig,
    ) {
        let seconds = report.status.is_scored().then_some(report.seconds);
        self.record(report, fitted, network);
        if let Some(last) = self.candidates.last_mut() {
            last.solo_seconds = seconds;
        }
    }

    fn record(
        &mut self,
        report: CandidateReport,
        fitted: Option<(CompressorConfig, FittedRegressor)>,
        network: RegressorConfig,
    ) {
        self.candidates.push(Candidate {
            report,
            network,
            fitted,
            solo_seconds: None,
        });
    }

    /// Every candidate's report, in the order tried.
    pub(super) fn reports(&self) -> Vec<CandidateReport> {
        self.candidates.iter().map(|c| c.report.clone()).collect()
    }

    /// The candidates that were fitted, best score first (ties keep the
    /// order in which they were tried).
    fn ranked(&self) -> Vec<usize> {
        let mut ranked: Vec<usize> = (0..self.candidates.len())
            .filter(|&i| self.candidates[i].report.status.is_scored())
            .collect();
        ranked.sort_by(|&a, &b| self.report(a).score.total_cmp(&self.report(b).score));
        ranked
    }

    /// The rows candidate `i` was fitted and scored on.
    pub(super) fn scored_rows(&self, i: usize) -> usize {
        self.report(i).fit_rows
    }

    /// Candidate `i`'s report.
    fn report(&self, i: usize) -> &CandidateReport {
        &self.candidates[i].report
    }

    /// The best candidate's index, among those fitted on the most rows
    /// (round 2's and 3's; a screened round-1 fit is not compared with
    /// them), or, if round 1 alone was fitted, among all: of those the
    /// seed alone could have ranked first (within [`Self::tie`] of the
    /// best score) and that no other beats on every parameter, the
    /// cheapest to fit. The time it leaves goes to round 3
    /// and to more records, which pay more than a difference the seed
    /// could have made: a costlier fit that wins by less than that leaves
    /// no time for round 3 or more records.
    /// With one parameter only the best score is beaten by none. Without
    /// a deadline (a budget in simulations), the best score.
    /// Round 3's averaged network loses to the network it averages where
    /// the records grow and the single network trains further on more of
    /// them in the same time ([`Self::equal_time`]).
    pub(super) fn best(&self, budget: &Budget) -> Result<usize> {
        let chosen = self.tied_best(budget)?;
        Ok(self.equal_time(chosen).map_or(chosen, |e| e.single))
    }

    /// [`Self::best`] before the comparison at equal final-fit time.
    pub(super) fn tied_best(&self, budget: &Budget) -> Result<usize> {
        let none_fitted = || {
            Error::setting(
                "budget",
                budget.describe(),
                format!(
                    "no candidate could be fitted within it (first: {})",
                    self.candidates
                        .first()
                        .map(|c| c.report.status.to_string())
                        .unwrap_or_default()
                ),
            )
        };
        if self.plan.deadline.is_none() {
            // Without a deadline the time a fit saves buys nothing, and a
            // choice by measured times would differ from run to run: the
            // same seed must give the same estimator on any machine.
            return self.best_score().ok_or_else(none_fitted);
        }
        let compared = self.on_most_rows();
        let score = |i: usize| self.report(i).score;
        let top = self.best_score().map(score);
        let beaten = |i: usize| {
            compared
                .iter()
                .any(|&j| beats_on_every_parameter(&self.report(j).rmse, &self.report(i).rmse))
        };
        compared
            .iter()
            .copied()
            .filter(|&i| top.is_some_and(|top| score(i) <= top * (1.0 + self.tie())) && !beaten(i))
            .min_by(|&a, &b| {
                let rows = self.report(a).fit_rows;
                self.fit_estimate(a, rows)
                    .total_cmp(&self.fit_estimate(b, rows))
                    .then(score(a).total_cmp(&score(b)))
            })
            .ok_or_else(none_fitted)
    }

    /// The best-scoring candidate among those fitted on the most rows.
    pub(super) fn best_score(&self) -> Option<usize> {
        self.on_most_rows()
            .into_iter()
            .min_by(|&a, &b| self.report(a).score.total_cmp(&self.report(b).score))
    }

    /// The scored candidates fitted on the most rows, in the order tried.
    fn on_most_rows(&self) -> Vec<usize> {
        let fitted = |i: &usize| self.report(*i).status.is_scored();
        let most_rows = (0..self.candidates.len())
            .filter(fitted)
            .map(|i| self.report(i).fit_rows)
            .max();
        (0..self.candidates.len())
            .filter(|i| fitted(i) && Some(self.report(*i).fit_rows) == most_rows)
            .collect()
    }

    /// Relative score difference within which candidates count as tied:
    /// the seed's measured spread, at least [`MIN_TIE`].
    fn tie(&self) -> f64 {
        self.seed_spread.unwrap_or(0.0).max(MIN_TIE)
    }

    /// The round-2 winner's rows and score on half its rows, where round 3
    /// measured them.
    pub(super) fn half_rows(&self) -> Option<(usize, f64)> {
        self.half_rows
    }

    /// How the round-2 winner's fit time grows with its rows, where round 3
    /// measured it.
    pub(super) fn rows_exponent(&self) -> Option<f64> {
        self.rows_exponent
    }
}

/// Whether RMSEs `a` are lower than `b` on every parameter (of as many
/// parameters, at least one).
fn beats_on_every_parameter(a: &[f64], b: &[f64]) -> bool {
    !a.is_empty() && a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x < y)
}

impl<S: Simulator + ?Sized> Plan<'_, '_, S> {
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
        self.base.progress().status(&format!(
            "search round {round}, candidate {} of {count}: {}; {}",
            k + 1,
            design(compressor, regressor),
            self.budget_words()
        ));
    }

    /// The budget for a progress line (the line gives the time).
    fn budget_words(&self) -> String {
        match self.budget {
            Budget::Seconds(t) => format!("budget {t:.0} s"),
            Budget::Simulations(_) => "every candidate runs".to_string(),
        }
    }

    /// Compress the chart with `compressor`, fit `regressor` on the first
    /// `rows` fitting rows at the run's seed moved by `seed_offset`, and
    /// score it on the held-out rows; skipped when `limit` (a deadline and
    /// the fit's estimated seconds) says it would not end in time.
    fn evaluate(
        &self,
        compressor: &CompressorConfig,
        regressor: &RegressorConfig,
        rows: usize,
        limit: Option<(Instant, f64)>,
        round: usize,
        seed_offset: u64,
    ) -> (CandidateReport, Option<(CompressorConfig, FittedRegressor)>) {
        let (chart, held_out) = (self.chart, self.fit_rows);
        let seed = self.base.seed().wrapping_add(seed_offset);
        let mut report = CandidateReport {
            compressor: compressor.to_string(),
            regressor: regressor.to_string(),
            design: design(compressor, regressor),
            trained_by: None,
            round,
            rmse: Vec::new(),
            score: f64::INFINITY,
            seconds: 0.0,
            fit_rows: rows,
            status: Status::Scored,
        };
        // (deadline, estimated seconds): skip what would not finish in time.
        if let Some((deadline, cost)) = limit
            && Instant::now() + Duration::from_secs_f64(cost) > deadline
        {
            report.status = Status::Skipped { seconds: cost };
            return (report, None);
        }
        let start = Instant::now();
        // A learned stage 1's network ends its epochs in time for the fit
        // after it and the rest of the search.
        let stop_by = limit.map(|(deadline, cost)| {
            let free = deadline
                .checked_sub(Duration::from_secs_f64(cost))
                .map_or(0.0, |end| {
                    end.saturating_duration_since(start).as_secs_f64()
                });
            start + Duration::from_secs_f64(LEARNED_SHARE * free)
        });
        // A structure the records cannot take (an autoregression of a
        // noise-free decay is rank deficient, a network longer than the
        // records) does not apply; only a fit that went wrong failed.
        let compressed = compressor
            .prepared_on(&chart.records[..rows])
            .and_then(|c| {
                c.trained_on(
                    chart.thetas.slice(ndarray::s![..rows, ..]),
                    &chart.records[..rows],
                    seed,
                    stop_by,
                )
            })
            .map_err(Error::from)
            .and_then(|c| {
                compress_all(&c, &chart.records, self.base.max_failure_fraction).map(|f| (c, f))
            });
        let (compressor, features) = match compressed {
            Ok(pair) => pair,
            Err(e) => {
                report.seconds = start.elapsed().as_secs_f64();
                report.status = Status::NotApplicable(e.to_string());
                return (report, None);
            }
        };
        let outcome = (|| -> Result<(Vec<f64>, f64, CompressorConfig, FittedRegressor)> {
            let (x_fit, x_held) = features.view().split_at(Axis(0), held_out);
            let (t_fit, t_held) = chart.thetas.view().split_at(Axis(0), held_out);
            let (x_fit, t_fit) = readable_rows(
                x_fit.slice_move(ndarray::s![..rows, ..]),
                t_fit.slice_move(ndarray::s![..rows, ..]),
            );
            let (x_held, t_held) = readable_rows(x_held, t_held);
            let prior = self.base.simulator().spec().prior();
            let z_fit = to_learning_space(t_fit.view(), prior.marginals());
            let fitted = regressor.fit(x_fit.view(), z_fit.view(), seed)?;
            let (rmse, score) = self.score(&fitted, x_held.view(), t_held.view())?;
            Ok((rmse, score, compressor.clone(), fitted))
        })();
        report.seconds = start.elapsed().as_secs_f64();
        match outcome {
            Ok((rmse, score, compressor, fitted)) => {
                report.trained_by = fitted.training_summary();
                report.score = score;
                report.rmse = rmse;
                (report, Some((compressor, fitted)))
            }
            Err(e) => {
                report.status = Status::Failed(e.to_string());
                (report, None)
            }
        }
    }

    /// Seconds until the deadline (infinite without one).
    fn seconds_left(&self) -> f64 {
        self.deadline.map_or(f64::INFINITY, |d| {
            d.saturating_duration_since(Instant::now()).as_secs_f64()
        })
    }

    /// RMSE per parameter of `fitted` on features `x` against parameters
    /// `thetas`, and its mean in units of the prior's sd.
    fn score(
        &self,
        fitted: &FittedRegressor,
        x: ndarray::ArrayView2<'_, f64>,
        thetas: ndarray::ArrayView2<'_, f64>,
    ) -> Result<(Vec<f64>, f64)> {
        let prior = self.base.simulator().spec().prior();
        let mut estimates = twostage_fit::Predictor::predict(fitted, x)?;
        rows_to_estimates(
            &mut estimates,
            prior.marginals(),
            prior.lower(),
            prior.upper(),
        );
        let rmse: Vec<f64> = (0..thetas.ncols())
            .map(|j| {
                let sq: f64 = thetas
                    .column(j)
                    .iter()
                    .zip(estimates.column(j))
                    .map(|(t, e)| (t - e).powi(2))
                    .sum();
                (sq / thetas.nrows().max(1) as f64).sqrt()
            })
            .collect();
        let score = rmse
            .iter()
            .zip(&self.prior_sd)
            .map(|(r, sd)| r / sd)
            .sum::<f64>()
            / rmse.len().max(1) as f64;
        Ok((rmse, score))
    }
}
