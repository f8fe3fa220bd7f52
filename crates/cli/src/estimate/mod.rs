//! `twostage estimate`: estimates of recorded experiments by an estimator
//! file or a classic method.

use std::path::PathBuf;

use anyhow::Result;
use twostage::{Estimating, RecordEstimate};

use crate::options::{InitialCovariance, TableFormat};
use crate::usage;

mod columns;
mod methods;
pub(crate) use methods::OUTSIDE_PRIOR_FLAGS;
mod said;

use columns::plot_check;

/// Options of `twostage estimate`.
#[derive(Debug, clap::Args)]
pub struct EstimateArgs {
    /// The estimator file written by `twostage train`.
    #[arg(long, conflicts_with_all = ["model", "method"])]
    estimator: Option<PathBuf>,
    /// Check each estimate (or --at's given values) against its record:
    /// the model's noise-free response there on the record's input, its
    /// RMS residual and normalized fit per output, the share of the
    /// model's own records there that miss by as much, and the share whose
    /// best fit would improve on the estimate as much as the record's best
    /// fit does. Not explained (said on stderr): a record whose best fit
    /// the model makes to its noise (above 1%) and improves on the
    /// estimate as at most 1% of them would; or, where not even the best
    /// fit does (a model that is not exact), one whose estimate is more
    /// than 5% in RMS from its best fit. Needs the model: an estimator's
    /// built-in one, or --model / --model-file.
    #[arg(long)]
    check: bool,
    /// With --check: the most of the model's own records each record is
    /// ranked among; the runs stop early (at 19, 39 or 99) once enough of
    /// them miss, and improve, by as much as the record that the verdict
    /// cannot change
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
    /// With --check: score up to this sample, not including it (counted
    /// from 0; default the record's end), leaving out a tail the model is
    /// not meant for.
    #[arg(long, value_name = "K")]
    score_to: Option<usize>,
    /// With --estimator: refine each estimate through the model. A
    /// built-in model: the posterior mean of its prediction-error
    /// likelihood over twice the interval (a grid of the likelihood;
    /// docs/accuracy.md, "Refinement", says what it costs). Any other
    /// model (--model-file): an output-error fit, Levenberg-Marquardt on
    /// the record minus the noise-free simulation, in the prior's box,
    /// from the estimate and two starts inside its interval (their
    /// simulations batched together), the estimate the mean of the
    /// likelihood near its best fit within the prior's box (the best fit
    /// where the record pins a parameter down, further inside where it
    /// leaves one loose by a bound of the box; with --check or
    /// --refine=auto, the best fit itself where the check finds that the
    /// model does not make the record even there); its own interval in
    /// _lo/_hi;
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
    /// estimates lie beyond their intervals from the others'). The records
    /// are taken to be of one plant: where their own best fits scatter
    /// beyond their noise (a model that misses part of the plant), the
    /// joint interval and each record's own include the scatter, and
    /// stderr says which parameters' widths it sets. With --refine, the
    /// records' refined estimates are pooled. Parameters marked
    /// `per_record = true` in the model file (an initial state, a sensor
    /// offset) are fitted once per record: then one row `joint[K]` per
    /// record K (counted from 0 in the order given) holds its own values
    /// beside the shared ones. Needs the model: an estimator's built-in
    /// one, or --model-file.
    #[arg(long, requires = "estimator")]
    joint: bool,
    /// With --refine, --joint or --samples: add the estimate's parameter
    /// correlations, a column `corr_A_B` per pair of parameters (empty
    /// where the refined estimate has no interval; with --samples, the
    /// draws').
    #[arg(long)]
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
    /// Given parameter values (a published value, a design value, another
    /// tool's estimate): a CSV with a column per parameter, as `estimate`
    /// writes it, its rows matched to the records by `experiment`, or one
    /// row for every record. With --check and the model (--model or
    /// --model-file): check them against the records instead of
    /// estimating. With --estimator and --samples: test them against each
    /// record's posterior (columns `region_level`, the smallest level of
    /// its joint region of highest density that holds them, and
    /// `in_region_90`).
    #[arg(long, value_name = "VALUES.csv", conflicts_with_all = ["method", "refine"])]
    at: Option<PathBuf>,
    /// With --at: accept values outside the model's prior box.
    #[arg(long, requires = "at")]
    allow_outside_prior: bool,
    /// With --estimator: hold a parameter at a value (NAME=VALUE,
    /// repeatable): the rows are of the others, and --check, --refine and
    /// --joint search them alone through the model with the value held,
    /// as an estimator trained with `train --fix` does (whose network
    /// also learned with it held: the two-stage estimates here did not).
    #[arg(long, value_name = "NAME=VALUE", requires = "estimator")]
    fix: Vec<String>,
    /// A classic method instead of an estimator: ekf, ukf, pf, pem, ii
    /// (indirect inference through the TS preset's ARX) or bayes for a
    /// built-in model; oe (a multi-start output-error fit: --starts draws
    /// from the prior, Levenberg-Marquardt on the record minus the
    /// noise-free simulation) for any model, --model or --model-file.
    #[arg(long, value_parser = methods::MethodChoice::parse)]
    method: Option<methods::MethodChoice>,
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
    /// Draw N parameter vectors from the estimator's posterior given each
    /// record (an estimator trained with --posterior; seeded by --seed
    /// and the record's place): the table gets each parameter's
    /// posterior mean and sd, --draws FILE the draws.
    #[arg(long, value_name = "N")]
    samples: Option<usize>,
    /// With --samples: sharpen each record's draws through the
    /// estimator's model (--model-file for one not built in) with M runs
    /// of it, in three rounds near the record's posterior: stage 1's
    /// features of the runs as a local Gaussian likelihood, times the
    /// prior. For posteriors narrower than the network resolves.
    #[arg(long, value_name = "M", requires = "samples")]
    sharpen: Option<usize>,
    /// With --samples: write every draw here (CSV: experiment, draw, a
    /// column per parameter).
    #[arg(long, value_name = "FILE", requires = "samples")]
    draws: Option<PathBuf>,
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

/// Run `twostage estimate`; returns how many records were estimated and
/// how many failed.
pub fn estimate(args: &EstimateArgs) -> Result<Outcome> {
    // `--refine auto` (a space) gives `auto` to the record files: clap
    // takes --refine's value only after `=`.
    if args.refine.is_some()
        && let Some(value) = args.data.first().and_then(|path| path.to_str())
        && ["auto", "all"].contains(&value)
        && !std::path::Path::new(value).exists()
    {
        return Err(usage(format!(
            "`--refine {value}` reads `{value}` as a record file: --refine takes its value \
             after `=`, write --refine={value}"
        )));
    }
    // Before the work: refined or checked records take minutes.
    for path in [&args.out, &args.draws].into_iter().flatten() {
        twostage::check_writable(path)?;
    }
    let estimating = methods::prepared(args)?;
    let format = estimating.record_format();
    let trained = estimating.trained_length();
    // Progress: a bar on a terminal, else a line every 10 s of a long step.
    let bars = crate::bars::Bars::new(false);
    let mut rows: Vec<(String, RecordEstimate)> = Vec::new();
    let mut failed = 0;
    let files = args
        .data
        .iter()
        .map(|path| estimating.read_file(path).map_err(anyhow::Error::msg));
    let mut said = said::Said::new(&format, trained);
    let joint = estimating.run(files, &bars, |file, estimates| {
        said.file(std::path::Path::new(file));
        if let Some(auto) = &estimates.auto {
            said.auto(auto, &estimates.rows);
        }
        for (id, outcome) in estimates.rows {
            said.note_length(&id, &outcome);
            match outcome {
                Ok((record, estimated)) => {
                    said.warnings(&id, &estimated);
                    if let (Some(dir), Some(Ok(check))) = (&args.plot, &estimated.check) {
                        plot_check(
                            dir,
                            &id,
                            &record,
                            check,
                            &format.outputs,
                            format.sample_time,
                        )?;
                    }
                    said.check(&id, &estimated);
                    rows.push((id, estimated));
                }
                Err(problem) => {
                    failed += 1;
                    eprintln!("error: {problem}");
                }
            }
        }
        Ok(())
    })?;
    said.summarize();
    if let Some(joint) = joint {
        // The rows so far are the gathered records', in their order.
        joint.widen(rows.iter_mut().map(|(_, row)| row));
        match (&joint.fit, joint.rows()) {
            (Ok((fit, _)), Ok(joint_rows)) => {
                let places: Vec<&str> = joint.places.iter().map(String::as_str).collect();
                said::joint(&places, estimating.param_names(), fit);
                rows.extend(joint_rows);
            }
            // No row: a joint row without an estimate would read as one.
            (_, Err(why)) | (Err(why), _) => {
                failed += 1;
                eprintln!(
                    "error: the joint fit of {} records failed: {why}",
                    joint.places.len()
                );
            }
        }
    }
    let outcome = Outcome {
        estimated: rows.len(),
        failed,
    };
    if rows.is_empty() && failed > 0 {
        // Nothing to write: an empty table would read as a result.
        return Ok(outcome);
    }
    write_table(args, &estimating, &rows)?;
    Ok(outcome)
}

/// The table of every estimated record, to `--out` or stdout.
fn write_table(
    args: &EstimateArgs,
    estimating: &Estimating,
    rows: &[(String, RecordEstimate)],
) -> Result<()> {
    let text = if args.format == TableFormat::Json {
        serde_json::to_string_pretty(&estimating.json(rows, args.correlation))? + "\n"
    } else {
        estimating.csv(rows, args.correlation)
    };
    match &args.out {
        Some(path) => twostage::write_whole(path, text.as_bytes())?,
        None => crate::standard_output::StandardOutput::write_text(&text)?,
    }
    if let Some(path) = &args.draws {
        twostage::write_whole(path, estimating.draws_csv(rows).as_bytes())?;
    }
    Ok(())
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
