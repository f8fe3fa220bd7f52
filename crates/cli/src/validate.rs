//! `twostage validate`: an estimator on fresh simulations of its model.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use ndarray::Array2;
use twostage::validate::rounds_listed;
use twostage::{Estimator, TargetRmse, Validated, ValidationPlan, validate_trained};

use crate::usage;

/// Most points drawn in the estimate-versus-truth figure.
const PLOTTED: usize = 2000;

/// Options of `twostage validate`.
#[derive(Debug, clap::Args)]
pub struct ValidateArgs {
    /// The estimator file.
    #[arg(long)]
    estimator: PathBuf,
    /// Number of fresh simulations r (with --target-rmse, the first round).
    #[arg(long, conflicts_with = "gamma")]
    sims: Option<usize>,
    /// Simulate until every certified RMSE is at most K times the observed
    /// one (from --sims, each round as many records as the last predicts,
    /// at most --max-sims). The certificate holds at every r at once, so
    /// stopping when it is met keeps its confidence.
    #[arg(long, value_name = "K", conflicts_with = "gamma")]
    target_rmse: Option<f64>,
    /// The most fresh simulations --target-rmse may run.
    #[arg(long, default_value_t = ValidationPlan::default().max_sims, requires = "target_rmse")]
    max_sims: usize,
    /// Accuracy gamma of Theorem 1: r is then the smallest size that
    /// guarantees it with confidence 1 - delta.
    #[arg(long, requires = "delta")]
    gamma: Option<f64>,
    /// Confidence parameter delta of Theorem 1.
    #[arg(long, default_value_t = ValidationPlan::default().delta)]
    delta: f64,
    /// Seed of the fresh simulations (disjoint from training by default).
    #[arg(long, default_value_t = ValidationPlan::DEFAULT_SEED)]
    seed: u64,
    /// Also draw estimates against truth into this SVG file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// The model file the estimator was trained from (needed unless it is
    /// of a built-in model).
    #[arg(long, value_name = "PATH")]
    model_file: Option<PathBuf>,
    #[command(flatten)]
    format: crate::options::FormatArgs,
}

/// Run `twostage validate`.
pub fn validate(args: &ValidateArgs, out: &mut dyn Write) -> Result<()> {
    let estimator = Estimator::load(&args.estimator)?;
    let given = crate::model_arg::named(None, args.model_file.as_deref())?;
    let plan = ValidationPlan {
        sims: args.sims,
        gamma: args.gamma,
        delta: args.delta,
        seed: args.seed,
        target_rmse: args.target_rmse,
        max_sims: args.max_sims,
    };
    // Progress: a bar on a terminal, else a line every 10 s of a long run.
    let bars = crate::bars::Bars::new(false);
    let run = validate_trained(&estimator, given.as_ref(), &plan, &bars).map_err(|e| {
        // What was asked for is the user's to fix, like a bad flag; the
        // model is the flag's.
        if matches!(
            e,
            twostage::Error::Source(twostage::sources::Error::OtherModel { .. })
        ) {
            usage(format!("--model-file: {e}"))
        } else if e.is_setting() {
            usage(e.to_string())
        } else {
            anyhow::Error::new(e).context("validating")
        }
    })?;
    let json = run.report_json()?;
    let Validated {
        report,
        truth,
        estimates,
        records: r,
        rounds,
        target,
        posterior,
    } = run;
    if let (Some(k), Some(target), false) = (args.target_rmse, target, args.format.json()) {
        match target {
            TargetRmse::Met { ratio } => writeln!(
                out,
                "--target-rmse {k}: met with r = {r} (every certified RMSE within {ratio:.3} \
                 times the observed; rounds ended at r = {})",
                rounds_listed(&rounds)
            )?,
            TargetRmse::NotMet { ratio } => writeln!(
                out,
                "--target-rmse {k}: not met with r = {r} = --max-sims (a certified RMSE is \
                 {ratio:.3} times the observed; rounds ended at r = {}): raise --max-sims",
                rounds_listed(&rounds)
            )?,
        }
    }
    if args.format.json() {
        writeln!(out, "{}", serde_json::to_string_pretty(&json)?)?;
    } else {
        writeln!(out, "{report}")?;
        if let Some(posterior) = &posterior {
            write!(out, "{}", posterior.describe(estimator.param_names()))?;
        }
    }
    let q = estimator.param_names().len();
    let truth = Array2::from_shape_vec((r, q), truth)?;
    let estimates = Array2::from_shape_vec((r, q), estimates)?;
    if let Some(path) = &args.plot {
        // Every record counts in the report; the figure shows at most
        // PLOTTED of them (every k-th), so the SVG stays small to open.
        let step = r.div_ceil(PLOTTED).max(1);
        let every = |v: ndarray::ArrayView1<'_, f64>| -> Vec<f64> {
            v.iter().step_by(step).copied().collect()
        };
        let columns: Vec<(Vec<f64>, Vec<f64>)> = (0..q)
            .map(|j| (every(truth.column(j)), every(estimates.column(j))))
            .collect();
        let shown = columns.first().map_or(0, |c| c.0.len());
        let panels: Vec<twostage_plot::Panel<'_>> = columns
            .iter()
            .zip(estimator.param_names())
            .enumerate()
            .map(|(j, ((t, e), name))| twostage_plot::Panel {
                caption: "",
                name,
                truth: t,
                estimate: e,
                range: (estimator.lower()[j], estimator.upper()[j]),
            })
            .collect();
        let title = if shown < r {
            format!(
                "{} estimator on {r} fresh simulations ({shown} shown)",
                estimator.training().model
            )
        } else {
            format!(
                "{} estimator on {r} fresh simulations",
                estimator.training().model
            )
        };
        let svg = twostage_plot::estimates_vs_truth(&title, &panels)?;
        twostage::write_whole(path, svg.as_bytes())?;
        if !args.format.json() {
            writeln!(out, "wrote {}", path.display())?;
        }
    }
    Ok(())
}
