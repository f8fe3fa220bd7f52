//! Automatic design: search stage-1 structures and network sizes by
//! validation error on simulated data, so that no human picks the ARX
//! order or the network (the paper leaves both to "a few trial-and-error
//! attempts").
//!
//! The chart is simulated once and its records kept; every candidate
//! compressor compresses them, every candidate network fits the same rows,
//! and all are scored on the same held-out rows; where the records'
//! inputs differ in kind, the last rival puts a summary network after the
//! best stage 1. The winner is refitted on
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

use std::time::Instant;

use twostage_estimator::Estimator;
use twostage_models::Simulator;
use twostage_train::{Error, Result};
use twostage_train::{TrainedOn, TwoStage};

use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;
use twostage_sources::ForModel;
use twostage_sources::Stage;
use twostage_sources::StoredChart;

mod candidates;
mod cost;
mod outcome;
use outcome::more_records_to_try;
mod search;
mod sizing;
use sizing::{MIN_SEARCH_RECORDS, SizedRun, chart_memory_cap, open_run};

use candidates::{
    candidate_compressors, constant_inputs, model_candidates, network, output_transforms, pieces,
};
use cost::slowest_pace;
pub use outcome::{
    AutoOutcome, CandidateReport, CheaperTie, Continuation, EqualTime, FinalFit, FinalFits,
    RivalNetwork, Status,
};
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

/// A budget choice [`Budget::chosen`] refuses; each door puts its own
/// name of the setting before these words.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BudgetChoiceError {
    /// A budget without the search, which alone reads it.
    #[error("a budget is read by the automatic design only: leave it out or search")]
    WithoutSearch,
    /// Both a time and a simulation budget.
    #[error("a budget is seconds or simulations: give one of them")]
    Both,
}

impl Budget {
    /// The search a door asks for: `search` whether it searches, with a
    /// budget of `seconds` or `simulations` (neither: [`Budget::default`]).
    /// Every door reads its choice here.
    ///
    /// ```
    /// use twostage_auto::{Budget, BudgetChoiceError};
    /// assert_eq!(Budget::chosen(false, None, None), Ok(None));
    /// assert_eq!(Budget::chosen(true, None, None), Ok(Some(Budget::default())));
    /// assert_eq!(Budget::chosen(true, None, Some(900)), Ok(Some(Budget::Simulations(900))));
    /// assert_eq!(Budget::chosen(false, Some(60.0), None), Err(BudgetChoiceError::WithoutSearch));
    /// assert_eq!(Budget::chosen(true, Some(60.0), Some(900)), Err(BudgetChoiceError::Both));
    /// ```
    ///
    /// # Errors
    /// A budget without the search, or two budgets.
    pub fn chosen(
        search: bool,
        seconds: Option<f64>,
        simulations: Option<usize>,
    ) -> std::result::Result<Option<Budget>, BudgetChoiceError> {
        match (search, seconds, simulations) {
            (false, None, None) => Ok(None),
            (false, _, _) => Err(BudgetChoiceError::WithoutSearch),
            (true, Some(_), Some(_)) => Err(BudgetChoiceError::Both),
            (true, None, Some(m)) => Ok(Some(Budget::Simulations(m))),
            (true, Some(t), None) => Ok(Some(Budget::Seconds(t))),
            (true, None, None) => Ok(Some(Budget::default())),
        }
    }

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

/// Builder of an automatic design for one simulator; see [`AutoDesign::new`].
#[derive(Debug)]
pub struct AutoDesign<'a, S: ?Sized> {
    base: TwoStage<'a, S>,
    budget: Budget,
    compressors: Option<Vec<CompressorConfig>>,
    networks: Option<(RegressorConfig, Vec<RegressorConfig>)>,
    /// Round 1's fitting rows where the user set them.
    screening_rows: Option<usize>,
}

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
            screening_rows: None,
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
    /// round 2 fits its networks, the round-1 network among them, on at
    /// least as many; only the fits on the most rows compete for the win.
    /// By default, where the source simulates more under a time budget,
    /// round 1 fits half of them and round 2 goes back to all of them where
    /// round 1 proved cheap against the budget; a number set
    /// here is fitted as it is.
    pub fn screening_rows(mut self, rows: usize) -> Self {
        self.screening_rows = Some(rows.max(1));
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
        let mut sized = open_run(base, budget, start)?;
        let charted = Instant::now();
        let (chart, rest, failures) = search_chart(&sized)?;
        sized.timed_chart(
            budget,
            start,
            (
                chart.records.len() + failures,
                charted.elapsed().as_secs_f64(),
            ),
        );
        let run = &sized.run;
        let records = run.records();
        let (medium, networks) = match networks {
            Some(pair) => pair,
            None => default_networks()?,
        };
        let spec = run.simulator().spec();
        let compressors = match compressors {
            Some(list) => shaped_for_model(list, run),
            None => {
                let constant = constant_inputs(&chart.records);
                if !constant.is_empty() {
                    let names: Vec<&str> = constant
                        .iter()
                        .map(|&j| spec.input_names().get(j).map_or("?", String::as_str))
                        .collect();
                    run.progress().note(&format!(
                        "the input(s) {} never vary within a training record: the ARX \
                         candidates regress on the outputs alone and the NARX is left out (no \
                         regression can fit lags of a constant input)",
                        names.join(", ")
                    ));
                }
                let mut list = candidate_compressors(
                    spec.output_names().len(),
                    spec.input_names().len(),
                    spec.n_samples(),
                    output_transforms(&chart.records),
                    constant.is_empty(),
                );
                list.extend(model_candidates(spec));
                list
            }
        };
        let scope = Scope::of(run);
        let mut search = Search::new(
            &scope,
            &chart,
            (budget, start, sized.deadline),
            screening_rows,
            records.can_grow(),
        );
        run.progress().begin(Stage::Fitting, 0);
        search.round_one(&compressors, &medium);
        search.round_two(&medium, &networks);
        let seed_scores = search.round_three(search.best(&budget)?);
        let half_rows = search.half_rows();
        let best = search.best(&budget)?;
        let equal_time = search.equal_time(search.tied_best(&budget)?);
        let cheaper_tie = search
            .best_score()
            .filter(|&top| top != best && equal_time.is_none())
            .map(|best_score| CheaperTie {
                picked: best,
                best_score,
            });
        let more_to_try = more_records_to_try(half_rows, seed_scores.first().copied());
        let (rows, more) = match rest {
            // A chart's records past the search's: all to the final fit.
            Some(rest) => (chart.records.len() + rest.records.len(), Some((rest, 0))),
            None => {
                let rows = search.final_rows(
                    best,
                    more_to_try,
                    sized.per_simulation.unwrap_or(f64::INFINITY),
                    chart_memory_cap(spec),
                );
                (rows, more_records(&sized, chart.records.len(), rows)?)
            }
        };
        let (added_simulations, added_failures) = match &more {
            Some((c, failed)) if sized.simulates => (c.records.len() + failed, *failed),
            _ => (0, 0),
        };
        let final_start = Instant::now();
        let scored_rows = search.scored_rows(best);
        let mut winner = search.winner(best, more.as_ref().map(|(c, _)| c), rows)?;
        // A larger network fitted anew on the final records may ship in
        // the winner's place.
        let best = winner.candidate;
        // Whatever the half-rows trial said: one comparison on a few
        // hundred rows can sit inside the seed's spread, where each step
        // measures for itself on records no fit saw.
        let (steps, step_simulations, step_failures) = if sized.simulates {
            let pace = final_pace(
                &winner.final_fit,
                scored_rows,
                final_start.elapsed().as_secs_f64(),
            );
            anytime_steps(
                &sized,
                &search,
                &mut winner,
                (sized.m + added_simulations, pace),
            )?
        } else {
            (Vec::new(), 0, 0)
        };
        let added_simulations = added_simulations + step_simulations;
        run.progress().end(Stage::Fitting);
        let search_seconds = start.elapsed().as_secs_f64();
        let failures = failures + added_failures + step_failures + winner.left_out;
        let simulations = winner.features.nrows() + failures;
        let final_fit = winner.final_fit;
        let estimator = ship(run, winner, failures)?;
        Ok(AutoOutcome {
            estimator,
            candidates: search.reports(),
            best,
            simulations,
            search_seconds,
            failures,
            final_fit,
            seed_scores,
            half_rows,
            added_simulations,
            rows_exponent: search.rows_exponent(),
            steps,
            cheaper_tie,
            equal_time,
        })
    }
}

/// The training records the search fits and scores on, and how many
/// simulations failed: a read chart's first `m` where it has more.
fn search_chart<S: Simulator + ?Sized>(
    sized: &SizedRun<'_, S>,
) -> Result<(StoredChart, Option<StoredChart>, usize)> {
    let (run, m) = (&sized.run, sized.m);
    let (mut chart, failures) = run.records().stored_training()?;
    let mut rest = None;
    if !sized.simulates && chart.records.len() > m {
        // Under a time budget the records past the search's reach the
        // winner's final fit: a chart cannot grow, and what the user gave
        // should all be learned from (trained further from the scored fit,
        // which the deadline may stop without making it worse).
        let kept = sized.deadline.is_some();
        run.progress().note(&format!(
            "the search fits and scores on the first {m} of the chart's {} training records \
             (as many as its budget affords){}",
            chart.records.len(),
            if kept {
                "; the winner's final fit takes them all"
            } else {
                "; a larger budget uses more"
            }
        ));
        let tail = StoredChart {
            thetas: chart.thetas.slice(ndarray::s![m.., ..]).to_owned(),
            records: chart.records.split_off(m),
        };
        chart.thetas = chart.thetas.slice(ndarray::s![..m, ..]).to_owned();
        rest = kept.then_some(tail);
    }
    if chart.records.len() < MIN_SEARCH_RECORDS {
        return Err(Error::setting(
            "training records",
            chart.records.len().to_string(),
            format!(
                "the automatic design needs at least {MIN_SEARCH_RECORDS} to fit on and \
                 score its candidates: give a larger chart, or hold out fewer records"
            ),
        ));
    }
    Ok((chart, rest, failures))
}

/// The medium network of round 1 and the others of round 2.
fn default_networks() -> Result<(RegressorConfig, Vec<RegressorConfig>)> {
    Ok((
        network(&[20])?,
        vec![
            network(&[10])?,
            network(&[40])?,
            network(&[20, 20])?,
            pieces(4, &[20])?,
        ],
    ))
}

/// The user's compressors shaped for the run's model; one the model
/// cannot take is named and left out.
fn shaped_for_model<S: Simulator + ?Sized>(
    list: Vec<CompressorConfig>,
    run: &twostage_train::Run<'_, S>,
) -> Vec<CompressorConfig> {
    let spec = run.simulator().spec();
    list.into_iter()
        .filter_map(|c| match c.for_model(spec) {
            Ok(shaped) => Some(shaped),
            Err(e) => {
                run.progress()
                    .note(&format!("the candidate {c} is left out: {e}"));
                None
            }
        })
        .collect()
}

/// The records simulated for the winner's final fit where it takes more
/// `rows` than the chart's `chart_rows`, and how many of them failed.
fn more_records<S: Simulator + ?Sized>(
    sized: &SizedRun<'_, S>,
    chart_rows: usize,
    rows: usize,
) -> Result<Option<(StoredChart, usize)>> {
    if rows <= chart_rows {
        return Ok(None);
    }
    let added = rows - chart_rows;
    simulate_more(
        sized,
        sized.m..sized.m + added,
        &format!("more records may pay: simulating {added} more for the winner's final fit"),
    )
}

/// The training experiments `designs` of the run's design, simulated
/// after a `note`, and how many failed; the fit's stage goes on after
/// them.
fn simulate_more<S: Simulator + ?Sized>(
    sized: &SizedRun<'_, S>,
    designs: std::ops::Range<usize>,
    note: &str,
) -> Result<Option<(StoredChart, usize)>> {
    let run = &sized.run;
    run.progress().note(note);
    let more = run.records().more_training(designs.start, designs.end)?;
    // The simulations ended their own stage: the fit goes on.
    run.progress().begin(Stage::Fitting, 0);
    Ok(more)
}

/// The anytime final fit's steps after the winner's final
/// fit, which took `last_seconds`: while the search's time lasts, more
/// records of the run's design from `next` on, the shipped fit trained
/// further on them; until [`UNPAID_STEPS_TO_END`] steps in a row do not
/// pay or the deadline stops one. The steps, and the simulations they
/// took and how many failed.
fn anytime_steps<S: Simulator + ?Sized>(
    sized: &SizedRun<'_, S>,
    search: &Search<'_, '_, S>,
    winner: &mut Winner,
    (mut next, mut pace): (usize, f64),
) -> Result<(Vec<Continuation>, usize, usize)> {
    let run = &sized.run;
    let per_simulation = sized.per_simulation.unwrap_or(f64::INFINITY);
    let cap = chart_memory_cap(run.simulator().spec());
    let (mut steps, mut simulations, mut failures) = (Vec::new(), 0, 0);
    let mut unpaid = 0;
    loop {
        let added = search.next_step_records(winner, pace, per_simulation, cap);
        if added == 0 {
            break;
        }
        let note = format!("time is left: simulating {added} more records for the final fit");
        let Some((more, failed)) = simulate_more(sized, next..next + added, &note)? else {
            break;
        };
        next += added;
        simulations += added;
        failures += failed;
        let begun = Instant::now();
        let step = search.step(winner, &more, added)?;
        pace = slowest_pace(
            Some(pace),
            begun.elapsed().as_secs_f64(),
            more.records.len(),
        );
        steps.push(step);
        let end;
        (end, unpaid) = steps_end(&step, unpaid);
        if end {
            break;
        }
    }
    Ok((steps, simulations, failures))
}

/// The seconds a record added cost the winner's final fit, which took
/// `seconds` in all: a fit anew's time over its rows, a fit trained
/// further's over the rows its start, fitted on `scored_rows`, had not
/// seen; over all its rows where it added none (the fit it was scored
/// with ships).
fn final_pace(final_fit: &FinalFit, scored_rows: usize, seconds: f64) -> f64 {
    let added = match *final_fit {
        FinalFit::Anew { rows } => rows,
        ref trained => trained.rows().saturating_sub(scored_rows),
    };
    let counted = if added == 0 { final_fit.rows() } else { added };
    slowest_pace(None, seconds, counted)
}

/// Anytime steps in a row that do not pay and end the steps: one step's
/// comparison on a few hundred records is too noisy to say alone that
/// more records no longer pay (a tie there ended runs at half the records
/// they reached otherwise). The records of a step that did not pay stay:
/// the next trains the fit kept on them and more.
const UNPAID_STEPS_TO_END: usize = 2;

/// Whether the anytime steps end after `step`, which followed `unpaid`
/// steps in a row that did not pay; and how many in a row have not paid
/// after it.
fn steps_end(step: &Continuation, unpaid: usize) -> (bool, usize) {
    let unpaid = if step.kept() { 0 } else { unpaid + 1 };
    (step.stopped || unpaid >= UNPAID_STEPS_TO_END, unpaid)
}

/// The winner, calibrated and validated by the run as a preset would be.
fn ship<S: Simulator + ?Sized>(
    run: &twostage_train::Run<'_, S>,
    winner: Winner,
    failures: usize,
) -> Result<Estimator> {
    let Winner {
        compressor,
        features,
        thetas,
        regressor_config,
        regressor,
        ..
    } = winner;
    let kept = features.nrows();
    run.finish(
        compressor,
        regressor,
        TrainedOn {
            features: features.view(),
            thetas: thetas.view(),
            simulations: kept + failures,
            failures,
            regressor: regressor_config,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step that scored `after` against `before`, stopped by the
    /// deadline or not.
    fn step(before: f64, after: f64, stopped: bool) -> Continuation {
        Continuation {
            simulations: 1000,
            rows: 800,
            compared: 200,
            before,
            after,
            stopped,
        }
    }

    #[test]
    fn the_final_fits_pace_counts_the_records_its_start_had_not_seen() {
        let pace = |fit: FinalFit| final_pace(&fit, 1000, 12.0).to_bits();
        // Trained further from a fit on 1000 rows to 4000: 3000 added.
        let further = FinalFit::TrainedFurther {
            rows: 4000,
            stopped: false,
        };
        assert_eq!(pace(further), 0.004f64.to_bits());
        // A fit anew saw none of its rows before.
        assert_eq!(pace(FinalFit::Anew { rows: 4000 }), 0.003f64.to_bits());
        // The fit it was scored with ships: its rows, not a division by
        // the none it added.
        assert_eq!(pace(FinalFit::AsScored { rows: 1000 }), 0.012f64.to_bits());
    }

    #[test]
    fn two_steps_in_a_row_that_do_not_pay_end_the_anytime_steps() {
        // A step that pays goes on and clears the count.
        assert_eq!(steps_end(&step(0.040, 0.039, false), 1), (false, 0));
        // A tie does not pay: the first goes on, the second in a row ends.
        assert_eq!(steps_end(&step(0.0384, 0.0384, false), 0), (false, 1));
        assert_eq!(steps_end(&step(0.038, 0.039, false), 1), (true, 2));
        // The deadline ends them whatever the step scored.
        assert_eq!(steps_end(&step(0.040, 0.039, true), 0), (true, 0));
    }
}
