//! `twostage estimate`: estimates of recorded experiments by an estimator
//! file or a classic method.

use std::path::PathBuf;

use anyhow::Result;
use rayon::prelude::*;
use twostage::Progress;
use twostage::fit::TerminationReason;
use twostage::models::IoData;
use twostage::models::Simulator;
use twostage::{BestFit, RecordCheck, RefineReason};

use crate::options::{InitialCovariance, TableFormat};
use crate::{csv_records, usage};

mod columns;
mod methods;
mod refine;
mod said;
mod table;

use columns::plot_check;
use methods::{Chosen, method};
use table::{PriorBox, csv, json};

/// Options of `twostage estimate`.
#[derive(Debug, clap::Args)]
pub struct EstimateArgs {
    /// The estimator file written by `twostage train`.
    #[arg(long, conflicts_with_all = ["model", "method"])]
    estimator: Option<PathBuf>,
    /// Check each estimate (or --at's given values) against its record:
    /// the model's noise-free response there on the record's input, its
    /// RMS residual and normalized fit per output, and the share of the
    /// model's own records there that miss by as much (a record at or
    /// below 1% is not explained, said on stderr). Needs the model: an
    /// estimator's built-in one, or --model / --model-file.
    #[arg(long)]
    check: bool,
    /// With --check: the most of the model's own records each record is
    /// ranked among; the runs stop early (at 19, 39 or 99) once enough of
    /// them miss by as much as the record that the verdict cannot change
    /// (`check_runs` says how many ran). Default 199.
    #[arg(long)]
    check_sims: Option<usize>,
    /// With --check: write DIR/EXPERIMENT.svg for each record, its outputs
    /// beside the model's noise-free response at the estimate.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// With --check: score from this sample on (counted from 0), leaving
    /// out the first samples of a transient: the misfits, fits and tail
    /// probability; the best fit is still fitted to the whole record.
    #[arg(long, value_name = "K")]
    score_from: Option<usize>,
    /// With --estimator: refine each estimate through the model. A
    /// built-in model: the posterior mean of its prediction-error
    /// likelihood over twice the interval (a grid of the likelihood;
    /// docs/accuracy.md, "Refinement", says what it costs). Any other
    /// model (--model-file): an output-error fit, Levenberg-Marquardt on
    /// the record minus the noise-free simulation, in the prior's box,
    /// from the estimate and two starts inside its interval (their
    /// simulations batched together); its own interval in _lo/_hi;
    /// `refine_stop` says why the best descent stopped, `optima` and `runner_up_over_best`
    /// what its search over the prior found. `--refine=auto`: check every
    /// two-stage estimate (as --check) and refine only the records it
    /// does not explain, named on stderr; the others keep their
    /// two-stage estimate, and every row carries the check's columns.
    #[arg(
        long,
        requires = "estimator",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "all",
        value_enum
    )]
    refine: Option<RefineWhich>,
    /// With --check, or --refine through a model file: the starts of the
    /// search for the model's best fit drawn over the prior (a Sobol
    /// design), besides the estimate and its interval's corners; default
    /// two per parameter and two more, 0 searches beside the estimate
    /// only. The check judges an estimate against that best fit, and the
    /// output-error refinement is that best fit (one search serves both).
    #[arg(long, value_name = "K")]
    prior_starts: Option<usize>,
    /// With --refine=auto: also refine a record whose fit (percent, on any
    /// output) is below this, however well the check explains it
    /// (default 0: the model at the estimate predicts worse than the
    /// record's mean).
    #[arg(
        long,
        value_name = "PERCENT",
        requires = "refine",
        allow_hyphen_values = true
    )]
    refine_below_fit: Option<f64>,
    /// With --estimator: one estimate of the plant behind every record of
    /// the files, written after the records' own as experiment `joint`:
    /// their two-stage estimates pooled by their intervals, then one
    /// output-error fit of all of them, each simulated on its own input
    /// (any length), searched from the pooled estimate, each record's
    /// estimate and the prior (--prior-starts), with its own interval in
    /// _lo/_hi. Stderr names the records fitted (with their fit there),
    /// left out (the model cannot run them) and disagreeing (their
    /// estimates lie beyond their intervals from the others'). Needs the
    /// model: an estimator's built-in one, or --model-file.
    #[arg(long, requires = "estimator", conflicts_with_all = ["refine", "check"])]
    joint: bool,
    /// With --refine or --joint: add the estimate's parameter correlations,
    /// a column `corr_A_B` per pair of parameters (empty where the
    /// refined estimate has no interval).
    #[arg(long, requires = "refine")]
    correlation: bool,
    /// With --method or --at: the built-in model the records come from
    /// (benchmark or pacejka).
    #[arg(long, conflicts_with = "model_file")]
    model: Option<String>,
    /// The model file the records come from: for --check with an
    /// estimator of a model file, with --at, or with --method (the classic
    /// methods exist for the built-in models only: it says so).
    #[arg(long, value_name = "PATH")]
    model_file: Option<PathBuf>,
    /// Check given parameter values instead of estimating them (a
    /// published value, another tool's estimate): a CSV with a column per
    /// parameter, as `estimate` writes it, its rows matched to the records
    /// by `experiment`, or one row for every record. Needs --check and the
    /// model (--model or --model-file).
    #[arg(
        long,
        value_name = "VALUES.csv",
        conflicts_with_all = ["estimator", "method", "refine"],
        requires = "check"
    )]
    at: Option<PathBuf>,
    /// With --at: accept values outside the model's prior box.
    #[arg(long, requires = "at")]
    allow_outside_prior: bool,
    /// A classic method instead of an estimator: ekf, ukf, pf, pem, ii
    /// (indirect inference through the TS preset's ARX) or bayes for a
    /// built-in model; oe (a multi-start output-error fit: --starts draws
    /// from the prior, Levenberg-Marquardt on the record minus the
    /// noise-free simulation) for any model, --model or --model-file.
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(
        twostage::ClassicMethod::ALL.map(|m| m.name()).into_iter().chain([OUTPUT_ERROR])
    ))]
    method: Option<String>,
    /// EKF/UKF initial covariance: the paper's eq. (6) or (7) (default eq6).
    #[arg(long, value_enum)]
    p0: Option<InitialCovariance>,
    /// Particle filter: number of particles (default 1000 benchmark, 500 car).
    #[arg(long)]
    particles: Option<usize>,
    /// Prediction error, indirect inference and output error: number of
    /// random starts (default 5).
    #[arg(long)]
    starts: Option<usize>,
    /// Seed of the random methods (pf, pem, ii, oe) and of --check's own
    /// records of the model (default 0).
    #[arg(long)]
    seed: Option<u64>,
    /// Estimate each window of N samples of every record instead of the
    /// record whole: one row per window, its last sample in a
    /// `window_end` column (counted from 1), as a control unit would
    /// re-estimate while the plant runs.
    #[arg(long, value_name = "N")]
    window: Option<usize>,
    /// With --window: a window every K samples (default N, windows side
    /// by side; the last window ends at the record's last full step).
    #[arg(long, value_name = "K", requires = "window")]
    every: Option<usize>,
    /// CSV files: header u,y (one record) or experiment,u,y (many).
    #[arg(required = true)]
    data: Vec<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = TableFormat::Csv)]
    format: TableFormat,
    /// Write the estimates here instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Which records `--refine` refines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum RefineWhich {
    /// Every record.
    All,
    /// The records whose two-stage estimate the check does not explain.
    Auto,
}

impl EstimateArgs {
    /// Whether the records are checked: --check, or `--refine=auto`, which
    /// checks to choose.
    fn checks(&self) -> bool {
        self.check || self.refine == Some(RefineWhich::Auto)
    }

    /// The best-fit search's starts for a model of `q` parameters.
    fn search(&self, q: usize) -> twostage::SearchStarts {
        twostage::SearchStarts {
            from_prior: self
                .prior_starts
                .unwrap_or_else(|| twostage::SearchStarts::default_from_prior(q)),
            seed: self.seed.unwrap_or(0),
        }
    }
}

/// One record's estimate, its interval half-widths and its feature
/// distance with the out-of-distribution threshold, where known.
struct Estimated {
    theta: Vec<f64>,
    widths: Option<Vec<f64>>,
    distance: Option<(f64, f64)>,
    /// How the record's input lies outside the estimator's input family
    /// (empty inside it), when the estimator knows one.
    input: Option<Vec<twostage::models::InputDeviation>>,
    /// Samples outside their output's transform, when the estimator
    /// transforms its outputs.
    floored: Option<Vec<twostage::compress::FlooredSample>>,
    /// With --check: how the model at the estimate explains the record, or
    /// why it could not be simulated.
    check: Option<Result<RecordCheck, String>>,
    /// With --refine: why an output-error descent stopped (`Ok(None)` for
    /// a posterior mean), or why the refinement failed (the TS estimate
    /// is kept).
    refined: Option<Result<Option<TerminationReason>, String>>,
    /// With --refine: why the refined estimate has no interval of its own.
    interval_failure: Option<String>,
    /// With --refine: the refined estimate's correlation matrix.
    correlation: Option<Vec<f64>>,
    /// With an output-error refinement or --joint: the optima its search
    /// ended in, and the runner-up's loss over the best's.
    optima: Option<(usize, Option<f64>)>,
    /// With --window: the window's last sample in its record, from 1.
    window_end: Option<usize>,
}

impl Estimated {
    /// Whether the record's input lies in the estimator's input family
    /// (`None` when it knows none).
    fn in_family(&self) -> Option<bool> {
        self.input.as_ref().map(Vec::is_empty)
    }

    /// Outside what training saw, by the features or by the input.
    fn out_of_distribution(&self) -> bool {
        self.distance.is_some_and(|(d, t)| d > t)
            || self.input.as_ref().is_some_and(|d| !d.is_empty())
    }
}

/// A record with its estimate, or why it has none.
type RecordOutcome = Result<(IoData, Estimated), String>;

/// Estimates one record (its experiment id and data), or says why it
/// cannot.
type Method = Box<dyn Fn(&str, &IoData) -> Result<Estimated, String> + Send + Sync>;

/// The name of the multi-start output-error fit among the methods.
const OUTPUT_ERROR: &str = "oe";

/// Run `twostage estimate`; returns how many records were estimated and
/// how many failed.
pub fn estimate(args: &EstimateArgs) -> Result<Outcome> {
    // Before the work: refined or checked records take minutes.
    if let Some(path) = &args.out {
        twostage::check_writable(path)?;
    }
    let chosen = method(args)?;
    // A check simulates the model many times per record; after an
    // output-error refinement, through the refinement's simulator (its
    // processes are already running).
    let check_model: Option<&dyn Simulator> = chosen
        .refiner
        .as_ref()
        .and_then(|r| r.simulator())
        .filter(|_| chosen.checker.is_some())
        .or(chosen.checker.as_deref());
    let session = Session {
        args,
        chosen: &chosen,
        check_model,
        plan: twostage::CheckPlan {
            noisy: args.check_sims.unwrap_or(twostage::DEFAULT_CHECK_RUNS),
            seed: args.seed.unwrap_or(0),
            score_from: args.score_from.unwrap_or(0),
            prior_starts: args.search(chosen.names.len()).from_prior,
        },
        policy: twostage::RefinePolicy {
            min_fit_percent: args
                .refine_below_fit
                .unwrap_or(twostage::RefinePolicy::default().min_fit_percent),
        },
        // Progress: a bar on a terminal, else a line every 10 s of a long
        // step.
        bars: crate::bars::Bars::new(false),
    };
    let mut rows: Vec<(String, Estimated)> = Vec::new();
    let mut failed = 0;
    // With --joint: every estimated record, by file and experiment.
    let mut plant: Vec<(String, IoData, usize)> = Vec::new();
    for path in &args.data {
        let mut estimates = session.estimate_file(path)?;
        session.check_and_refine(path, &mut estimates);
        let mut said = said::Said::new(path, &chosen.format, chosen.trained);
        for (id, outcome) in estimates {
            said.note_length(&id, &outcome);
            match outcome {
                Ok((record, estimated)) => {
                    said.warnings(&id, &estimated);
                    if let (Some(dir), Some(Ok(check))) = (&args.plot, &estimated.check) {
                        let format = &chosen.format;
                        plot_check(
                            dir,
                            &id,
                            &record,
                            check,
                            &format.signals.outputs,
                            format.sample_time,
                        )?;
                    }
                    said.check(&id, &estimated);
                    if chosen.joint.is_some() {
                        let name = format!("{}: experiment {id}", path.display());
                        plant.push((name, record, rows.len()));
                    }
                    rows.push((id, estimated));
                }
                Err(problem) => {
                    failed += 1;
                    eprintln!("error: {problem}");
                }
            }
        }
        said.summarize();
    }
    if let Some(fitter) = &chosen.joint
        && !plant.is_empty()
    {
        let joint = joint_of_plant(fitter, &plant, &rows, &session.bars);
        rows.push(("joint".into(), joint));
    }
    let outcome = Outcome {
        estimated: rows.len(),
        failed,
    };
    if rows.is_empty() && failed > 0 {
        // Nothing to write: an empty table would read as a result.
        return Ok(outcome);
    }
    write_table(args, &chosen, &rows)?;
    Ok(outcome)
}

/// What every file of one `estimate` run shares: the method, the check's
/// model and plan, the progress bars.
struct Session<'a> {
    args: &'a EstimateArgs,
    chosen: &'a Chosen,
    check_model: Option<&'a dyn Simulator>,
    plan: twostage::CheckPlan,
    /// Which two-stage estimates `--refine=auto` refines.
    policy: twostage::RefinePolicy,
    bars: crate::bars::Bars,
}

/// A record's best-fit search, or why it failed; `None` where no check or
/// refinement needs one.
type Search = Option<Result<BestFit, String>>;

impl Session<'_> {
    /// Every record of the file at `path` estimated, in parallel, reported
    /// in their order: each estimate depends on its record alone.
    fn estimate_file(&self, path: &std::path::Path) -> Result<Vec<(String, RecordOutcome)>> {
        let reads = csv_records::read(path, &self.chosen.format).map_err(anyhow::Error::msg)?;
        let pieces = self.windows(path, reads)?;
        self.bars.begin_step("estimating", pieces.len(), "records");
        let estimates = pieces
            .into_par_iter()
            .map(|(id, record, window_end)| {
                let estimated = record.and_then(|record| {
                    let estimated = (self.chosen.method)(&id, &record)
                        .map_err(|e| format!("{}: experiment {id}: {e}", path.display()))?;
                    Ok((
                        record,
                        Estimated {
                            window_end,
                            ..estimated
                        },
                    ))
                });
                self.bars.advance_step(1);
                (id, estimated)
            })
            .collect();
        self.bars.end_step();
        Ok(estimates)
    }

    /// The records to estimate: each whole, or with --window each of its
    /// windows (its last sample, from 1, beside it). A record shorter than
    /// one window is refused by name.
    #[allow(clippy::type_complexity)]
    fn windows(
        &self,
        path: &std::path::Path,
        reads: Vec<csv_records::ReadRecord>,
    ) -> Result<Vec<(String, Result<IoData, String>, Option<usize>)>> {
        let Some(window) = self.args.window else {
            return Ok(reads.into_iter().map(|r| (r.id, r.record, None)).collect());
        };
        let every = self.args.every.unwrap_or(window);
        if window == 0 || every == 0 {
            return Err(usage(format!(
                "--window {window} --every {every}: give a window and a step of at least 1 sample"
            )));
        }
        let mut pieces = Vec::new();
        for read in reads {
            let record = match read.record {
                Ok(record) => record,
                Err(e) => {
                    pieces.push((read.id, Err(e), None));
                    continue;
                }
            };
            let n = record.n_samples();
            if n < window {
                pieces.push((
                    read.id.clone(),
                    Err(format!(
                        "{}: experiment {}: {n} samples, shorter than the window of {window}",
                        path.display(),
                        read.id
                    )),
                    None,
                ));
                continue;
            }
            for end in (window..=n).step_by(every) {
                pieces.push((
                    read.id.clone(),
                    Ok(record.window(end - window, end)),
                    Some(end),
                ));
            }
        }
        Ok(pieces)
    }

    /// The file's estimates checked and refined as asked. One best-fit
    /// search per record serves its check and its output-error
    /// refinement. With `--refine=auto` the two-stage estimates are
    /// checked first and only the records the policy names are refined
    /// (and checked again).
    fn check_and_refine(&self, path: &std::path::Path, estimates: &mut [(String, RecordOutcome)]) {
        let everyone = vec![true; estimates.len()];
        let searches = self.search(estimates);
        match (&self.chosen.refiner, self.args.refine) {
            (Some(refiner), Some(RefineWhich::Auto)) => {
                self.check_all(estimates, &everyone, &searches);
                let reasons = self.reasons(estimates);
                let chosen: Vec<bool> = reasons.iter().map(Option::is_some).collect();
                let explained = estimates
                    .iter()
                    .filter(|(_, outcome)| {
                        matches!(outcome, Ok((_, e)) if matches!(&e.check, Some(Ok(c)) if c.explained()))
                    })
                    .count();
                eprintln!(
                    "note: {}: --refine=auto: the check explains {} of {} two-stage estimates; \
                     refining {}",
                    path.display(),
                    explained,
                    everyone.len(),
                    said::refine_reasons(estimates, &reasons)
                );
                refine_together(refiner, estimates, &chosen, &searches, &self.bars);
                self.check_all(estimates, &chosen, &searches);
            }
            (Some(refiner), _) => {
                refine_together(refiner, estimates, &everyone, &searches, &self.bars);
                self.check_all(estimates, &everyone, &searches);
            }
            (None, _) => self.check_all(estimates, &everyone, &searches),
        }
    }

    /// Each record's best-fit search (from its estimate, its interval's
    /// corners and the prior), where a check or an output-error refinement
    /// needs one: the records of a file together, in lockstep, a batch of
    /// them at a time.
    fn search(&self, estimates: &[(String, RecordOutcome)]) -> Vec<Search> {
        let refiner = self.chosen.refiner.as_ref().filter(|r| r.is_output_error());
        let Some(model) = refiner.and_then(|r| r.simulator()).or(self.check_model) else {
            return vec![None; estimates.len()];
        };
        let prior = model.spec().prior();
        let starts: Vec<Option<Result<Vec<Vec<f64>>, String>>> = estimates
            .iter()
            .map(|(_, outcome)| {
                let (_, e) = outcome.as_ref().ok()?;
                let widths = e.widths.as_deref();
                Some(match refiner {
                    Some(r) => r.search_starts(prior, &e.theta, widths),
                    None => self
                        .plan
                        .search()
                        .starts(prior, &e.theta, widths)
                        .map_err(|e| e.to_string()),
                })
            })
            .collect();
        let wanted = starts.iter().filter(|s| matches!(s, Some(Ok(_)))).count();
        self.bars.begin_step("searching", wanted, "records");
        let mut found = Vec::with_capacity(wanted);
        let searches: Vec<(&IoData, Vec<Vec<f64>>)> = estimates
            .iter()
            .zip(&starts)
            .filter_map(|((_, outcome), starts)| {
                let (record, _) = outcome.as_ref().ok()?;
                Some((record, starts.as_ref()?.as_ref().ok()?.clone()))
            })
            .collect();
        let mut searches = searches.into_iter();
        loop {
            let chunk: Vec<_> = searches.by_ref().take(twostage::RECORDS_TOGETHER).collect();
            if chunk.is_empty() {
                break;
            }
            let k = chunk.len();
            found.extend(twostage::search_best_fits(model, chunk));
            self.bars.advance_step(k);
        }
        self.bars.end_step();
        let mut found = found.into_iter();
        starts
            .into_iter()
            .map(|starts| match starts? {
                Ok(_) => Some(
                    found
                        .next()
                        .unwrap_or_else(|| unreachable!("one search per record with starts"))
                        .map_err(|e| format!("the best-fit search failed: {e}")),
                ),
                Err(e) => Some(Err(e)),
            })
            .collect()
    }

    /// Why `--refine=auto` refines each record (`None`: it keeps its
    /// two-stage estimate): the policy's reasons, from the check, the
    /// feature distance and the record's length.
    fn reasons(&self, estimates: &[(String, RecordOutcome)]) -> Vec<Option<RefineReason>> {
        estimates
            .iter()
            .map(|(_, outcome)| {
                let (record, e) = outcome.as_ref().ok()?;
                let other_length = self.chosen.trained.is_some_and(|n| n != record.n_samples());
                match &e.check {
                    Some(Ok(c)) => self.policy.reason(c, e.out_of_distribution(), other_length),
                    _ => other_length.then_some(RefineReason::OtherLength),
                }
            })
            .collect()
    }

    /// Check the estimates of the records marked in `only`, in parallel,
    /// against their searches.
    fn check_all(
        &self,
        estimates: &mut [(String, RecordOutcome)],
        only: &[bool],
        searches: &[Search],
    ) {
        let Some(model) = self.check_model else {
            return;
        };
        self.bars
            .begin_step("checking", only.iter().filter(|o| **o).count(), "records");
        estimates
            .par_iter_mut()
            .zip(only)
            .zip(searches)
            .filter(|((_, only), _)| **only)
            .for_each(|(((_, outcome), _), search)| {
                if let Ok((record, estimated)) = outcome {
                    estimated.check = Some(check(model, record, estimated, search, self.plan));
                }
                self.bars.advance_step(1);
            });
        self.bars.end_step();
    }
}

/// The table of every estimated record, to `--out` or stdout.
fn write_table(args: &EstimateArgs, chosen: &Chosen, rows: &[(String, Estimated)]) -> Result<()> {
    let outputs = &chosen.format.signals.outputs;
    let prior_box = chosen.prior_box.as_ref();
    let text = if args.format == TableFormat::Json {
        json(&chosen.names, rows, outputs, args.correlation, prior_box)?
    } else {
        csv(&chosen.names, rows, outputs, args.correlation, prior_box)?
    };
    match &args.out {
        Some(path) => twostage::write_whole(path, text.as_bytes())?,
        None => crate::standard_output::StandardOutput::write_text(&text)?,
    }
    Ok(())
}

/// Refines the estimated records of a file together: an output-error
/// refinement at each record's best fit from its search, a posterior
/// refinement by its own grid (their simulations in shared batches). A
/// refinement that fails keeps the TS estimate, and says so; one that
/// succeeds brings its own interval (NaN where the record does not
/// determine it, said on stderr).
fn refine_together(
    refiner: &twostage::EstimateRefiner,
    estimates: &mut [(String, RecordOutcome)],
    only: &[bool],
    searches: &[Search],
    bars: &crate::bars::Bars,
) {
    let (items, bests): (Vec<twostage::ToRefine<'_>>, Vec<Result<BestFit, String>>) = estimates
        .iter()
        .zip(only)
        .zip(searches)
        .filter(|((_, only), _)| **only)
        .filter_map(|(((_, outcome), _), search)| {
            let (record, e) = outcome.as_ref().ok()?;
            let best = search
                .clone()
                .unwrap_or_else(|| Err("no best-fit search".into()));
            Some(((record, e.theta.as_slice(), e.widths.as_deref()), best))
        })
        .unzip();
    bars.begin_step("refining", items.len(), "records");
    let refined = if refiner.is_output_error() {
        let refined = refiner.refine_at(&items, &bests);
        bars.advance_step(items.len());
        refined
    } else {
        refiner.refine_many_reporting(&items, bars)
    };
    bars.end_step();
    let estimated = estimates
        .iter_mut()
        .zip(only)
        .filter(|(_, only)| **only)
        .filter_map(|((_, outcome), _)| outcome.as_mut().ok());
    for ((_, e), result) in estimated.zip(refined) {
        match result {
            Ok(r) => {
                let q = r.theta.len();
                let (own, why) = match r.half_widths {
                    Ok(w) => (w, None),
                    Err(why) => (vec![f64::NAN; q], Some(why)),
                };
                e.theta = r.theta;
                e.widths = Some(own);
                e.refined = Some(Ok(r.stop));
                e.interval_failure = why;
                e.correlation = r.correlation;
                e.optima = r.optima;
            }
            Err(why) => e.refined = Some(Err(why)),
        }
    }
}

/// The joint estimate of every record of `plant` (its name, the record
/// and its row among `rows`), said on stderr record by record; a joint
/// fit that fails keeps the pooled two-stage estimate, and says why.
fn joint_of_plant(
    fitter: &twostage::JointFitter,
    plant: &[(String, IoData, usize)],
    rows: &[(String, Estimated)],
    bars: &crate::bars::Bars,
) -> Estimated {
    let items: Vec<twostage::ToRefine<'_>> = plant
        .iter()
        .map(|(_, record, row)| {
            let e = &rows[*row].1;
            // An estimate out of the estimator's distribution has no
            // interval to weigh it by: it only starts the search.
            let widths = e.widths.as_deref().filter(|_| !e.out_of_distribution());
            (record, e.theta.as_slice(), widths)
        })
        .collect();
    bars.begin_step("fitting jointly", 1, "plants");
    let found = fitter.fit(&items);
    bars.advance_step(1);
    bars.end_step();
    let joint = match found {
        Ok(joint) => joint,
        Err(why) => {
            eprintln!(
                "error: the joint fit of {} records failed: {why}",
                plant.len()
            );
            return Estimated {
                refined: Some(Err(why)),
                ..methods::bare(Vec::new())
            };
        }
    };
    said::joint(plant, &joint);
    let q = joint.theta.len();
    let (widths, why) = match joint.half_widths {
        Ok(w) => (w, None),
        Err(why) => (vec![f64::NAN; q], Some(why)),
    };
    Estimated {
        widths: Some(widths),
        refined: Some(Ok(Some(joint.stop))),
        interval_failure: why,
        correlation: joint.correlation,
        optima: Some((joint.optima, joint.runner_up_ratio)),
        ..methods::bare(joint.theta)
    }
}

/// Checks one record's estimate against the record's best-fit search.
fn check(
    model: &dyn Simulator,
    record: &IoData,
    estimated: &Estimated,
    search: &Search,
    plan: twostage::CheckPlan,
) -> Result<RecordCheck, String> {
    let best = search
        .as_ref()
        .ok_or_else(|| "no best-fit search".to_string())?
        .as_ref()
        .map_err(Clone::clone)?;
    twostage::check_against(model, record, &estimated.theta, best, plan).map_err(|e| e.to_string())
}

/// How many records were estimated, and how many could not be.
pub struct Outcome {
    /// Records estimated and written.
    pub estimated: usize,
    /// Records that could not be (each said on stderr).
    pub failed: usize,
}

impl Outcome {
    /// The closing line when some record failed; `None` when none did.
    pub fn failure(&self) -> Option<String> {
        match (self.failed, self.estimated) {
            (0, _) => None,
            (failed, 0) => Some(format!(
                "no record could be estimated ({failed} listed above); nothing was written"
            )),
            (failed, estimated) => Some(format!(
                "{failed} record(s) could not be estimated (listed above); the other \
                 {estimated} were, and are written"
            )),
        }
    }
}
