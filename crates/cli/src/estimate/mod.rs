//! `twostage estimate`: estimates of recorded experiments by an estimator
//! file or a classic method.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use rayon::prelude::*;
use twostage::fit::TerminationReason;
use twostage::models::Simulator;
use twostage::models::{BuiltinModel, IoData};
use twostage::{Estimator, ModelProfile, OutputError, RecordCheck, SignalNames};

use crate::number::format_f64;
use crate::options::{InitialCovariance, TableFormat};
use crate::{csv_records, usage};

mod columns;
mod refine;

use columns::{check_fields, check_header, input_as_trained, list, plot_check, refine_stop};
use refine::{model_of, refinement};

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

/// The model named by --model or --model-file, which `what` needs.
fn named_model(args: &EstimateArgs, what: &str) -> Result<twostage::NamedModel> {
    match (&args.model_file, &args.model) {
        (Some(path), _) => twostage::NamedModel::file(path),
        (None, Some(model)) => twostage::NamedModel::builtin(model),
        (None, None) => {
            return Err(usage(format!(
                "{what} simulates the model: give --model M or --model-file F"
            )));
        }
    }
    .map_err(|e| usage(e.to_string()))
}

/// Refuses an option that the chosen way of estimating would not read:
/// an option silently ignored reads as one that worked.
fn refuse_what_does_not_apply(args: &EstimateArgs) -> Result<()> {
    let method = args.method.as_deref();
    let running = match (method, &args.estimator, &args.at) {
        (Some(m), _, _) => format!("--method {m}"),
        (None, Some(_), _) => "an estimator".to_string(),
        (None, None, Some(_)) => "--at".to_string(),
        (None, None, None) => return Ok(()),
    };
    let is = |names: &[&str]| method.is_some_and(|m| names.contains(&m));
    let refuse = |option: &str, readers: &str| {
        Err(usage(format!(
            "{option} is read by {readers}; {running} does not read it: leave it out"
        )))
    };
    if (args.check_sims.is_some() || args.plot.is_some() || args.score_from.is_some())
        && !args.checks()
    {
        return refuse(
            "--check-sims, --plot and --score-from",
            "--check and --refine=auto",
        );
    }
    if args.model.is_some() && method.is_none() && args.at.is_none() {
        return refuse(
            "--model",
            "--method and --at (an estimator knows its model)",
        );
    }
    if args.p0.is_some() && !is(&["ekf", "ukf"]) {
        return refuse("--p0", "--method ekf and ukf");
    }
    if args.particles.is_some() && !is(&["pf"]) {
        return refuse("--particles", "--method pf");
    }
    if args.starts.is_some() && !is(&["pem", "ii", OUTPUT_ERROR]) {
        return refuse("--starts", "--method pem, ii and oe");
    }
    if args.seed.is_some() && !args.checks() && !is(&["pf", "pem", "ii", OUTPUT_ERROR]) {
        return refuse("--seed", "--method pf, pem, ii and oe, and --check");
    }
    Ok(())
}

/// The signals of a model's records, as its CSV files name them.
fn record_format(spec: &twostage::models::ModelSpec) -> csv_records::RecordFormat {
    csv_records::RecordFormat {
        signals: SignalNames {
            inputs: spec.input_names().to_vec(),
            outputs: spec.output_names().to_vec(),
        },
        sample_time: spec.sample_time(),
    }
}

/// An estimate that is nothing but its parameters.
fn bare(theta: Vec<f64>) -> Estimated {
    Estimated {
        theta,
        widths: None,
        distance: None,
        floored: None,
        check: None,
        refined: None,
        interval_failure: None,
        correlation: None,
    }
}

/// `--method oe`: a multi-start output-error fit of any model that can
/// run without noise on a given input.
fn output_error_method(args: &EstimateArgs) -> Result<Chosen> {
    let named = named_model(args, "--method oe")?;
    let simulator = named.simulator(false).map_err(|e| usage(e.to_string()))?;
    let format = record_format(simulator.spec());
    let names = simulator.spec().param_names().to_vec();
    let checker = check_model(args)?;
    let fit = OutputError::new(simulator).map_err(|e| usage(format!("--method oe: {e}")))?;
    let oe = twostage_baselines::PredictionError::new(fit, args.starts.unwrap_or(DEFAULT_STARTS))
        .seed(args.seed.unwrap_or(0))
        .named(OUTPUT_ERROR);
    Ok(Chosen {
        names,
        format,
        trained: None,
        checker,
        refiner: None,
        prior_box: None,
        method: Box::new(move |_, record: &IoData| {
            let best = oe
                .descents(record)
                .map_err(|e| e.to_string())?
                .into_iter()
                .next()
                .ok_or_else(|| "no start".to_string())?;
            Ok(Estimated {
                refined: Some(Ok(Some(best.stop))),
                ..bare(best.theta)
            })
        }),
    })
}

/// `--at VALUES.csv`: given values, one row for every record or a row per
/// experiment, to be checked.
fn given_values(args: &EstimateArgs, path: &std::path::Path) -> Result<Chosen> {
    let named = named_model(args, "--at")?;
    let simulator = named.simulator(false).map_err(|e| usage(e.to_string()))?;
    let spec = simulator.spec().clone();
    let rows = crate::predict::read_rows(path, spec.param_names())?;
    crate::predict::refuse_outside_prior(&rows, &spec, path, args.allow_outside_prior)?;
    let file = path.display().to_string();
    let one = (rows.len() == 1).then(|| rows[0].theta.clone());
    let mut by_id = std::collections::HashMap::new();
    if one.is_none() {
        for row in rows {
            let id = row.id.clone();
            if by_id.insert(row.id, row.theta).is_some() {
                return Err(usage(format!(
                    "{file}: experiment {id} has two rows of values: give one per experiment"
                )));
            }
        }
    }
    let values = move |id: &str| match &one {
        Some(theta) => Ok(theta.clone()),
        None => by_id.get(id).cloned().ok_or_else(|| {
            format!(
                "{file} has no row for experiment {id}: give a row per experiment, or a single \
                 row for every record"
            )
        }),
    };
    Ok(Chosen {
        names: spec.param_names().to_vec(),
        format: record_format(&spec),
        trained: None,
        checker: Some(simulator),
        refiner: None,
        prior_box: None,
        method: Box::new(move |id, _| values(id).map(bare)),
    })
}

/// The model --check simulates for --method and --at: --model or
/// --model-file.
fn check_model(args: &EstimateArgs) -> Result<Option<Box<dyn Simulator>>> {
    if !args.check {
        return Ok(None);
    }
    let named = named_model(args, "--check")?;
    Ok(Some(
        named.simulator(false).map_err(|e| usage(e.to_string()))?,
    ))
}

/// The most runs of the model's own records a check ranks a record among
/// when --check-sims is not given.
const DEFAULT_CHECK_SIMS: usize = 199;

/// Starts of the multi-start methods when --starts is not given.
const DEFAULT_STARTS: usize = 5;

/// What a record is estimated with: the parameter names, the method, the
/// record length an estimator file was trained and validated on, the
/// signals (the CSV columns) it reads, and the model --check simulates.
struct Chosen {
    names: Vec<String>,
    method: Method,
    trained: Option<usize>,
    format: csv_records::RecordFormat,
    checker: Option<Box<dyn Simulator>>,
    /// With --refine: the refinement of an estimator's estimates, run over
    /// a file's records together.
    refiner: Option<twostage_baselines::EstimateRefiner>,
    /// The prior's box, which the intervals stay inside.
    prior_box: Option<PriorBox>,
}

/// The lower and upper corners of a prior's box.
type PriorBox = (Vec<f64>, Vec<f64>);

/// A row's interval as written: `theta +- widths` inside the prior's box.
fn interval(e: &Estimated, prior_box: Option<&PriorBox>) -> Option<(Vec<f64>, Vec<f64>)> {
    let widths = e.widths.as_ref()?;
    Some(match prior_box {
        Some((lower, upper)) => twostage::interval_in_box(&e.theta, widths, lower, upper),
        None => e
            .theta
            .iter()
            .zip(widths)
            .map(|(t, w)| (t - w, t + w))
            .unzip(),
    })
}

/// The method chosen on the command line, ready to estimate records.
fn method(args: &EstimateArgs) -> Result<Chosen> {
    use twostage_baselines as b;
    refuse_what_does_not_apply(args)?;
    if let Some(path) = &args.estimator {
        let estimator = Estimator::load(path)?;
        let names = estimator.param_names().to_vec();
        let trained = estimator.record_shape().n_samples;
        let format = csv_records::RecordFormat {
            signals: estimator.signal_names(),
            sample_time: estimator.record_shape().sample_time,
        };
        let transforms = estimator.transforms_outputs();
        let checker = if args.checks() {
            Some(model_of(&estimator, args)?)
        } else {
            None
        };
        let refiner = if args.refine.is_some() {
            Some(refinement(&estimator, args)?)
        } else {
            None
        };
        let prior_box = Some((estimator.lower().to_vec(), estimator.upper().to_vec()));
        return Ok(Chosen {
            names,
            format,
            trained: Some(trained),
            checker,
            refiner,
            prior_box,
            method: Box::new(move |_, record: &IoData| {
                let a = estimator.assess(record).map_err(|e| e.to_string())?;
                // The adaptive intervals have the same level and follow the
                // record; the fixed ones are the fallback. Both were
                // calibrated for the TS estimate, not a refined one.
                Ok(Estimated {
                    distance: a.feature_distance.zip(a.distance_threshold),
                    widths: a.interval_half_widths().map(<[f64]>::to_vec),
                    theta: a.theta,
                    floored: transforms.then_some(a.floored_samples),
                    ..bare(Vec::new())
                })
            }),
        });
    }
    if let Some(path) = &args.at {
        return given_values(args, path);
    }
    if args.method.as_deref() == Some(OUTPUT_ERROR) {
        return output_error_method(args);
    }
    if let (Some(path), Some(name)) = (&args.model_file, &args.method) {
        let file = twostage::ModelFile::load(path).map_err(|e| usage(e.to_string()))?;
        return Err(usage(format!(
            "method '{name}' is not available for {}: the classic methods exist for the \
             built-in models only; train an estimator with `twostage train --model-file`",
            file.name()
        )));
    }
    let (Some(model), Some(name)) = (&args.model, &args.method) else {
        return Err(usage(
            "give --estimator FILE, --model M --method ekf|ukf|pf|pem|ii|bayes, or --model M \
             --at VALUES.csv --check"
                .into(),
        ));
    };
    let model: BuiltinModel = model.parse().map_err(|e| usage(format!("{e}")))?;
    let simulator = model.build(false)?;
    let names = simulator.param_names().to_vec();
    let format = record_format(simulator.spec());
    let method = ModelProfile::of(model)
        .classic_method(name)
        .map_err(|e| usage(e.to_string()))?;
    let settings = b::MethodSettings {
        initial_covariance: args.p0.unwrap_or(InitialCovariance::Eq6).into(),
        particles: args.particles,
        starts: args.starts.unwrap_or(DEFAULT_STARTS),
        seed: args.seed.unwrap_or(0),
    };
    let estimator = b::classic_estimator(model, method, &settings)?;
    Ok(Chosen {
        names,
        format,
        trained: None,
        checker: check_model(args)?,
        refiner: None,
        prior_box: None,
        method: Box::new(move |_, record: &IoData| {
            estimator
                .estimate(record)
                .map(|e| bare(e.theta))
                .map_err(|e| e.to_string())
        }),
    })
}

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
                let unexplained: Vec<bool> = estimates
                    .iter()
                    .map(|(_, outcome)| {
                        matches!(outcome, Ok((_, e)) if matches!(&e.check, Some(Ok(c)) if !c.explained()))
                    })
                    .collect();
                let ids: Vec<&str> = estimates
                    .iter()
                    .zip(&unexplained)
                    .filter(|(_, u)| **u)
                    .map(|((id, _), _)| id.as_str())
                    .collect();
                eprintln!(
                    "note: {}: --refine=auto: the check explains {} of {} two-stage estimates; \
                     refining {}{}",
                    path.display(),
                    everyone.len() - ids.len(),
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
                    "warning: {}: experiment {id}: {} samples, the estimator was trained and \
                     validated on N = {trained}; its accuracy and intervals may not hold",
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

/// The pairs of parameters a correlation column names, `corr_A_B` with A
/// before B, with their place in the row-major matrix.
fn correlation_pairs(names: &[String]) -> Vec<(String, usize)> {
    let q = names.len();
    (0..q)
        .flat_map(|a| (a + 1..q).map(move |b| (a, b)))
        .map(|(a, b)| (format!("corr_{}_{}", names[a], names[b]), a * q + b))
        .collect()
}

fn csv(
    names: &[String],
    rows: &[(String, Estimated)],
    outputs: &[String],
    with_correlation: bool,
    prior_box: Option<&PriorBox>,
) -> Result<String> {
    use twostage::sources::csv_rows::row;
    let with_intervals = rows.iter().any(|(_, e)| e.widths.is_some());
    let with_distance = rows.iter().any(|(_, e)| e.distance.is_some());
    let mut header = vec!["experiment".to_string()];
    header.extend(names.iter().cloned());
    if with_intervals {
        for n in names {
            header.push(format!("{n}_lo"));
            header.push(format!("{n}_hi"));
        }
    }
    if with_distance {
        header.extend(["feature_distance".into(), "out_of_distribution".into()]);
    }
    let with_floored = rows.iter().any(|(_, e)| e.floored.is_some());
    if with_floored {
        header.push("untransformed_samples".into());
    }
    let with_check = rows.iter().any(|(_, e)| e.check.is_some());
    if with_check {
        header.extend(check_header(outputs));
    }
    let with_stop = rows
        .iter()
        .any(|(_, e)| matches!(e.refined, Some(Ok(Some(_))) | Some(Err(_))));
    if with_stop {
        header.push("refine_stop".into());
    }
    let pairs = if with_correlation {
        correlation_pairs(names)
    } else {
        Vec::new()
    };
    header.extend(pairs.iter().map(|(name, _)| name.clone()));
    let mut text = row(&header);
    for (id, e) in rows {
        let mut fields = vec![id.clone()];
        fields.extend(e.theta.iter().map(|t| format_f64(*t)));
        if let Some((lo, hi)) = interval(e, prior_box) {
            for (lo, hi) in lo.iter().zip(&hi) {
                fields.push(format_f64(*lo));
                fields.push(format_f64(*hi));
            }
        }
        if let Some((d, _)) = e.distance {
            fields.push(format_f64(d));
            fields.push(e.out_of_distribution().to_string());
        }
        if with_floored {
            fields.push(e.floored.as_ref().map_or(0, Vec::len).to_string());
        }
        if with_check {
            fields.extend(check_fields(outputs.len(), e.check.as_ref()));
        }
        if with_stop {
            fields.push(refine_stop(e.refined.as_ref()));
        }
        for (_, at) in &pairs {
            fields.push(
                e.correlation
                    .as_ref()
                    .map_or_else(String::new, |r| format_f64(r[*at])),
            );
        }
        text.push_str(&row(&fields));
    }
    Ok(text)
}

fn json(
    names: &[String],
    rows: &[(String, Estimated)],
    outputs: &[String],
    with_correlation: bool,
    prior_box: Option<&PriorBox>,
) -> Result<String> {
    let pairs = if with_correlation {
        correlation_pairs(names)
    } else {
        Vec::new()
    };
    let records: Vec<serde_json::Value> = rows
        .iter()
        .map(|(id, e)| {
            let mut object = serde_json::Map::new();
            object.insert("experiment".into(), id.clone().into());
            let bounds = interval(e, prior_box);
            for (j, n) in names.iter().enumerate() {
                object.insert(n.clone(), e.theta[j].into());
                if let Some((lo, hi)) = &bounds {
                    object.insert(format!("{n}_lo"), lo[j].into());
                    object.insert(format!("{n}_hi"), hi[j].into());
                }
            }
            if let Some((d, _)) = e.distance {
                object.insert("feature_distance".into(), d.into());
                object.insert("out_of_distribution".into(), e.out_of_distribution().into());
            }
            if let Some(floored) = &e.floored {
                object.insert("untransformed_samples".into(), floored.len().into());
            }
            if matches!(e.refined, Some(Ok(Some(_))) | Some(Err(_))) {
                object.insert("refine_stop".into(), refine_stop(e.refined.as_ref()).into());
            }
            if let Some(r) = &e.correlation {
                for (name, at) in &pairs {
                    object.insert(name.clone(), r[*at].into());
                }
            }
            match &e.check {
                Some(Ok(c)) => {
                    for (j, y) in outputs.iter().enumerate() {
                        object.insert(format!("{y}_rms"), c.rms[j].into());
                        object.insert(format!("{y}_fit_percent"), c.fit_percent[j].into());
                    }
                    object.insert("check_tail_probability".into(), c.tail_probability.into());
                    object.insert("check_runs".into(), c.reference_runs.into());
                    object.insert("model_consistent".into(), c.model_consistent().into());
                    object.insert("loss_over_best".into(), c.loss_ratio.into());
                    object.insert("explained".into(), c.explained().into());
                    if let Some(same) = input_as_trained(c) {
                        object.insert("input_as_trained".into(), same.into());
                    }
                }
                Some(Err(e)) => {
                    object.insert("check_error".into(), e.clone().into());
                }
                None => {}
            }
            serde_json::Value::Object(object)
        })
        .collect();
    Ok(serde_json::to_string_pretty(&records)? + "\n")
}
