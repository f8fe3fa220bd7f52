//! `twostage estimate`: estimates of recorded experiments by an estimator
//! file or a classic method.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use rayon::prelude::*;
use twostage::RecordCheck;
use twostage::fit::TerminationReason;
use twostage::models::IoData;
use twostage::models::Simulator;

use crate::csv_records;
use crate::options::{InitialCovariance, TableFormat};

mod columns;
mod methods;
mod refine;
mod table;

use columns::{list, plot_check};
use methods::{Chosen, DEFAULT_CHECK_SIMS, method};
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
    /// likelihood over twice the interval (about 1 ms per benchmark
    /// record, 0.4 s per car record). Any other model (--model-file): an
    /// output-error fit, Levenberg-Marquardt on the record minus the
    /// noise-free simulation, in the prior's box, from the estimate and
    /// two starts inside its interval (their simulations batched together);
    /// its own interval in _lo/_hi (decision 035); `refine_stop` says
    /// why the best descent stopped. `--refine=auto`: check every
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
    /// With --refine: add the refined estimate's parameter correlations,
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
}

/// One record's estimate, its interval half-widths and its feature
/// distance with the out-of-distribution threshold, where known.
struct Estimated {
    theta: Vec<f64>,
    widths: Option<Vec<f64>>,
    distance: Option<(f64, f64)>,
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
}

impl Estimated {
    fn out_of_distribution(&self) -> bool {
        self.distance.is_some_and(|(d, t)| d > t)
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
    let Chosen {
        names,
        method: estimate_one,
        trained: trained_samples,
        format,
        checker,
        refiner,
        prior_box,
    } = method(args)?;
    let seed = args.seed.unwrap_or(0);
    let plan = twostage::CheckPlan {
        noisy: args.check_sims.unwrap_or(DEFAULT_CHECK_SIMS),
        seed,
        score_from: args.score_from.unwrap_or(0),
        at_best_fit: false,
    };
    // Progress: a bar on a terminal, else a line every 10 s of a long step.
    let bars = crate::bars::Bars::new(false);
    let with_correlation = args.correlation;
    let mut rows: Vec<(String, Estimated)> = Vec::new();
    let mut failed = 0;
    let output_names = format.signals.outputs.clone();
    let sample_time = format.sample_time;
    for path in &args.data {
        let reads = csv_records::read(path, &format).map_err(|e| anyhow::anyhow!(e))?;
        // The records in parallel, reported in their order: each estimate
        // depends on its record alone.
        bars.begin_step("estimating", reads.len(), "records");
        let mut estimates: Vec<(String, RecordOutcome)> = reads
            .into_par_iter()
            .map(|read| {
                let estimated = read.record.and_then(|record| {
                    let estimated = estimate_one(&read.id, &record)
                        .map_err(|e| format!("{}: experiment {}: {e}", path.display(), read.id))?;
                    Ok((record, estimated))
                });
                bars.advance_step(1);
                (read.id, estimated)
            })
            .collect();
        bars.end_step();
        // A check simulates the model many times per record; after an
        // output-error refinement, through the refinement's simulator (its
        // processes are already running).
        let check_model: Option<&dyn Simulator> = refiner
            .as_ref()
            .and_then(|r| r.simulator())
            .filter(|_| checker.is_some())
            .or(checker.as_deref());
        let check_all = |estimates: &mut Vec<(String, RecordOutcome)>, only: &[bool]| {
            let Some(model) = check_model else {
                return;
            };
            bars.begin_step("checking", only.iter().filter(|o| **o).count(), "records");
            estimates
                .par_iter_mut()
                .zip(only)
                .filter(|(_, only)| **only)
                .for_each(|((_, outcome), _)| {
                    if let Ok((record, estimated)) = outcome {
                        estimated.check = Some(check(model, record, estimated, plan));
                    }
                    bars.advance_step(1);
                });
            bars.end_step();
        };
        let everyone = vec![true; estimates.len()];
        match (&refiner, args.refine) {
            (Some(refiner), Some(RefineWhich::Auto)) => {
                // The two-stage estimates first; the records the check does
                // not explain are refined, and checked again.
                check_all(&mut estimates, &everyone);
                // A record of another length than the estimator's is
                // refined whatever the check says: the two-stage estimate
                // keeps its length.
                let unexplained: Vec<bool> = estimates
                    .iter()
                    .map(|(_, outcome)| match outcome {
                        Ok((record, e)) => {
                            matches!(&e.check, Some(Ok(c)) if !c.explained())
                                || trained_samples.is_some_and(|n| n != record.n_samples())
                        }
                        Err(_) => false,
                    })
                    .collect();
                let ids: Vec<&str> = estimates
                    .iter()
                    .zip(&unexplained)
                    .filter(|(_, u)| **u)
                    .map(|((id, _), _)| id.as_str())
                    .collect();
                let explained = estimates
                    .iter()
                    .filter(|(_, outcome)| {
                        matches!(outcome, Ok((_, e)) if matches!(&e.check, Some(Ok(c)) if c.explained()))
                    })
                    .count();
                eprintln!(
                    "note: {}: --refine=auto: the check explains {} of {} two-stage estimates; \
                     refining {}{}",
                    path.display(),
                    explained,
                    everyone.len(),
                    if ids.is_empty() {
                        "none"
                    } else {
                        "experiment(s) "
                    },
                    list_ids(&ids)
                );
                refine_together(refiner, &mut estimates, &unexplained, &bars);
                check_all(&mut estimates, &unexplained);
            }
            (Some(refiner), _) => {
                refine_together(refiner, &mut estimates, &everyone, &bars);
                check_all(&mut estimates, &everyone);
            }
            (None, _) => check_all(&mut estimates, &everyone),
        }
        // A failure every record shares (a simulator that does not start)
        // is said once, with the others counted: 200 identical lines would
        // hide everything else.
        let mut repeated = RepeatedFailures::default();
        for (id, outcome) in estimates {
            // The estimate is still defined, but the validation error and
            // the intervals were measured for another N (said only of a
            // record that was estimated: a failed one says why).
            if let (Ok((record, _)), Some(trained)) = (&outcome, trained_samples)
                && record.n_samples() != trained
            {
                eprintln!(
                    "note: {}: experiment {id}: {} samples, the estimator was trained and \
                     validated on N = {trained}: its estimate only starts the refinement, \
                     which fits the record at its own length",
                    path.display(),
                    record.n_samples()
                );
            }
            match outcome {
                Ok((record, estimated)) => {
                    if let Some((d, t)) = estimated.distance.filter(|(d, t)| d > t) {
                        eprintln!(
                            "warning: {}: experiment {}: out of distribution: its features lie \
                             at Mahalanobis distance {d:.3} from the training features, beyond \
                             the {t:.3} that 99.9% of them stay within; the estimate extrapolates \
                             and the intervals do not cover it (is it the same model and input?)",
                            path.display(),
                            id
                        );
                    }
                    if let Some(floored) = estimated.floored.as_ref().filter(|f| !f.is_empty()) {
                        let listed: Vec<String> = floored
                            .iter()
                            .take(5)
                            .map(|f| {
                                let signal = output_names.get(f.output).map_or("?", String::as_str);
                                format!("{signal} = {} at sample {}", f.value, f.sample + 1)
                            })
                            .collect();
                        eprintln!(
                            "warning: {}: experiment {}: {} sample(s) outside the domain of the \
                             estimator's output transform ({}{}), taken at the smallest value \
                             the training records had; the estimate and its intervals do not \
                             speak for them",
                            path.display(),
                            id,
                            floored.len(),
                            listed.join(", "),
                            if floored.len() > 5 { ", ..." } else { "" }
                        );
                    }
                    match &estimated.refined {
                        Some(Err(e)) if repeated.first("--refine", e, &id) => eprintln!(
                            "warning: {}: experiment {}: --refine failed ({e}); the two-stage \
                             estimate is kept",
                            path.display(),
                            id
                        ),
                        Some(Ok(Some(TerminationReason::MaxIterations))) => eprintln!(
                            "warning: {}: experiment {}: --refine did not converge within its \
                             iterations; the estimate is the best point it reached",
                            path.display(),
                            id
                        ),
                        _ => {}
                    }
                    if let Some(e) = &estimated.interval_failure {
                        eprintln!(
                            "warning: {}: experiment {}: the refined estimate has no interval \
                             ({e}); its _lo and _hi are NaN",
                            path.display(),
                            id
                        );
                    }
                    if let (Some(Ok(_)), Some(Ok(check))) = (&estimated.refined, &estimated.check)
                        && !check.model_consistent()
                    {
                        eprintln!(
                            "note: {}: experiment {}: the model does not make this record \
                             exactly (model_consistent false): the refined interval covers this \
                             record's noise about the model's best fit, not the error of the \
                             model itself, so the plant's true values may lie outside it",
                            path.display(),
                            id
                        );
                    }
                    if let (Some(dir), Some(Ok(check))) = (&args.plot, &estimated.check) {
                        plot_check(dir, &id, &record, check, &output_names, sample_time)?;
                    }
                    // Only an estimator learned one input; a check simulates on
                    // the record's own.
                    if let (
                        Some(Ok(RecordCheck {
                            input_differs_at: Some((j, k)),
                            ..
                        })),
                        Some(_),
                    ) = (&estimated.check, trained_samples)
                    {
                        eprintln!(
                            "warning: {}: experiment {}: its input {} differs from the one every \
                             training record had (from sample {}): the estimator learned that \
                             input and does not read this one, so its estimate is not for this \
                             record; train on this experiment's input, or on an input design",
                            path.display(),
                            id,
                            format.signals.inputs.get(*j).map_or("?", String::as_str),
                            k + 1
                        );
                    }
                    match &estimated.check {
                        Some(Err(e)) if repeated.first("--check", e, &id) => eprintln!(
                            "warning: {}: experiment {}: --check could not simulate the model at \
                             the estimate ({e}); the estimate is kept, unchecked",
                            path.display(),
                            id
                        ),
                        Some(Ok(c)) if !c.explained() => eprintln!(
                            "warning: {}: experiment {}: not explained by the model at its \
                             estimate: RMS residual {}, fit {} %, where the model fits {} % near \
                             it, and at most {:.1}% of its own records there miss by as much; do \
                             not trust this estimate (another input than training's, or a poor \
                             estimate: try --refine; docs/real-data.md)",
                            path.display(),
                            id,
                            list(&c.rms),
                            list(&c.fit_percent),
                            list(&c.best_fit_percent),
                            100.0 * c.tail_probability
                        ),
                        Some(Ok(c)) if !c.model_consistent() => eprintln!(
                            "note: {}: experiment {}: the estimate fits the record as well as the \
                             model can near it (fit {} %), but not to the model's own noise (at \
                             most {:.1}% of its records miss by as much): the model is not exact \
                             for this record; judge it by predicting a record it was not fitted \
                             to (docs/real-data.md)",
                            path.display(),
                            id,
                            list(&c.fit_percent),
                            100.0 * c.tail_probability
                        ),
                        _ => {}
                    }
                    rows.push((id, estimated));
                }
                Err(problem) => {
                    failed += 1;
                    eprintln!("error: {problem}");
                }
            }
        }
        repeated.summarize(&path.display().to_string());
    }
    let outcome = Outcome {
        estimated: rows.len(),
        failed,
    };
    if rows.is_empty() && failed > 0 {
        // Nothing to write: an empty table would read as a result.
        return Ok(outcome);
    }
    let text = if args.format == TableFormat::Json {
        json(
            &names,
            &rows,
            &output_names,
            with_correlation,
            prior_box.as_ref(),
        )?
    } else {
        csv(
            &names,
            &rows,
            &output_names,
            with_correlation,
            prior_box.as_ref(),
        )?
    };
    match &args.out {
        Some(path) => twostage::write_whole(path, text.as_bytes())?,
        None => std::io::stdout().lock().write_all(text.as_bytes())?,
    }
    Ok(outcome)
}

/// Refines the estimated records of a file together (their simulations in
/// shared batches): a refinement that fails keeps the TS estimate, and says
/// so; one that succeeds brings its own interval (NaN where the record does
/// not determine it, said on stderr).
fn refine_together(
    refiner: &twostage_baselines::EstimateRefiner,
    estimates: &mut [(String, RecordOutcome)],
    only: &[bool],
    bars: &crate::bars::Bars,
) {
    let items: Vec<twostage_baselines::ToRefine<'_>> = estimates
        .iter()
        .zip(only)
        .filter(|(_, only)| **only)
        .filter_map(|((_, outcome), _)| outcome.as_ref().ok())
        .map(|(record, e)| (record, e.theta.as_slice(), e.widths.as_deref()))
        .collect();
    bars.begin_step("refining", items.len(), "records");
    let refined = refiner.refine_many_reporting(&items, &|k| bars.advance_step(k));
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
            }
            Err(why) => e.refined = Some(Err(why)),
        }
    }
}

/// Checks one record's estimate; an output-error refinement that converged
/// is the best fit near itself, and the check need not descend again.
fn check(
    model: &dyn Simulator,
    record: &IoData,
    estimated: &Estimated,
    plan: twostage::CheckPlan,
) -> Result<RecordCheck, String> {
    let at_best_fit = matches!(
        estimated.refined,
        Some(Ok(Some(TerminationReason::Converged)))
    );
    twostage::check_with(
        model,
        record,
        &estimated.theta,
        twostage::CheckPlan {
            at_best_fit,
            ..plan
        },
    )
    .map_err(|e| e.to_string())
}

/// Experiment ids for a message: the first ten, and how many more.
fn list_ids(ids: &[&str]) -> String {
    let shown = ids.iter().take(10).copied().collect::<Vec<_>>().join(", ");
    if ids.len() > 10 {
        format!("{shown} and {} more", ids.len() - 10)
    } else {
        shown
    }
}

/// Failures of --refine or --check seen before: the first of each kind
/// and message is said in full, the others only counted.
#[derive(Default)]
struct RepeatedFailures {
    /// (what failed, message) -> (the first experiment, the others).
    seen: std::collections::BTreeMap<(&'static str, String), (String, Vec<String>)>,
}

impl RepeatedFailures {
    /// Whether this failure is the first of its kind and message (to be
    /// said in full); a repeat is counted.
    fn first(&mut self, what: &'static str, message: &str, id: &str) -> bool {
        match self.seen.get_mut(&(what, message.to_string())) {
            Some((_, others)) => {
                others.push(id.to_string());
                false
            }
            None => {
                self.seen
                    .insert((what, message.to_string()), (id.to_string(), Vec::new()));
                true
            }
        }
    }

    /// One line per repeated failure: how many more records, which.
    fn summarize(&self, file: &str) {
        for ((what, _), (first, others)) in &self.seen {
            if others.is_empty() {
                continue;
            }
            let ids: Vec<&str> = others.iter().map(String::as_str).collect();
            eprintln!(
                "warning: {file}: {what} failed as for experiment {first} in {} more \
                 experiment(s): {}",
                others.len(),
                list_ids(&ids)
            );
        }
    }
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
