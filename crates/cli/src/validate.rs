//! `twostage validate`: an estimator on fresh simulations of its model.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use ndarray::Array2;
use rayon::prelude::*;
use twostage::models::{IoData, Sampling, run_experiment};
use twostage::sources::refuse_beyond_memory;
use twostage::validate::{ValidationReport, hoeffding_sample_size, squared_error_bound};
use twostage::{EstimateWorkspace, Estimator, NamedModel};

use crate::OrUsage;
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
    /// one (doubling r from --sims, at most --max-sims). The certificate
    /// holds at every r at once, so stopping when it is met keeps its
    /// confidence.
    #[arg(long, value_name = "K", conflicts_with = "gamma")]
    target_rmse: Option<f64>,
    /// The most fresh simulations --target-rmse may run.
    #[arg(long, default_value_t = 1_000_000, requires = "target_rmse")]
    max_sims: usize,
    /// Accuracy gamma of Theorem 1: r is then the smallest size that
    /// guarantees it with confidence 1 - delta.
    #[arg(long, requires = "delta")]
    gamma: Option<f64>,
    /// Confidence parameter delta of Theorem 1.
    #[arg(long, default_value_t = 1e-3)]
    delta: f64,
    /// Seed of the fresh simulations (disjoint from training by default).
    #[arg(long, default_value_t = 0x5641_4c49)]
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
    let trained_on = &estimator.training().model;
    let given = crate::model_arg::named(None, args.model_file.as_deref())?;
    let sim = NamedModel::trained_on(trained_on, given.as_ref())
        .and_then(|model| model.simulator(false))
        .usage_context("--model-file")?;
    let sigma = squared_error_bound(estimator.lower(), estimator.upper());
    let mut r = match (args.sims, args.gamma) {
        (Some(r), _) => r,
        (None, Some(gamma)) => usize::try_from(
            hoeffding_sample_size(sigma, gamma, args.delta).usage_context("--gamma/--delta")?,
        )
        .map_err(|_| usage("--gamma is too small: the sample size overflows".into()))?,
        (None, None) => 1000,
    };
    if r == 0 {
        return Err(usage("--sims must be at least 1".into()));
    }
    let most = match args.target_rmse {
        Some(k) if !(k.is_finite() && k > 1.0) => {
            return Err(usage(format!(
                "--target-rmse {k}: a certified RMSE is never below the observed one; \
                 give a multiple above 1, such as 1.5"
            )));
        }
        Some(_) if args.max_sims < r => {
            return Err(usage(format!(
                "--max-sims {} is below the first round of {r} simulations",
                args.max_sims
            )));
        }
        Some(_) => args.max_sims,
        None => r,
    };
    let q = estimator.param_names().len();
    // Theorem 1 and the certificate assume independent draws from the
    // prior, whatever design the model trains with. Record i depends only
    // on (seed, i), so each round extends the one before.
    let prior = sim.prior().clone().with_sampling(Sampling::Uniform);
    // Each record's parameters in the design, and its truth and estimate.
    let flag = if args.target_rmse.is_some() {
        "--max-sims"
    } else {
        "--sims"
    };
    refuse_beyond_memory(
        flag,
        most,
        8 * 3 * q as u64,
        "records' parameters and estimates",
    )
    .or_usage()?;
    let design = prior.design(most, args.seed)?;
    let (mut truth, mut estimates) = (Vec::new(), Vec::new());
    let report = loop {
        let done = truth.len() / q;
        let pairs: Vec<(Vec<f64>, Vec<f64>)> = (done..r)
            .into_par_iter()
            .map_init(
                || (IoData::default(), EstimateWorkspace::new()),
                |(record, work), i| -> Result<(Vec<f64>, Vec<f64>)> {
                    let mut theta = vec![0.0; q];
                    run_experiment(sim.as_ref(), &design, i, &mut theta, record)?;
                    let mut estimate = vec![0.0; q];
                    estimator.estimate_into(
                        record.inputs(),
                        record.outputs(),
                        work,
                        &mut estimate,
                    )?;
                    Ok((theta, estimate))
                },
            )
            .collect::<Result<_>>()?;
        for (theta, estimate) in pairs {
            truth.extend(theta);
            estimates.extend(estimate);
        }
        let report = ValidationReport::new(
            estimator.param_names(),
            ndarray::ArrayView2::from_shape((r, q), &truth)?,
            ndarray::ArrayView2::from_shape((r, q), &estimates)?,
            estimator.lower(),
            estimator.upper(),
            args.delta,
            estimator.intervals().cloned(),
        )?;
        let Some(k) = args.target_rmse else {
            break report;
        };
        let ratio = certified_ratio(&report);
        if ratio <= k {
            if !args.format.json() {
                writeln!(
                    out,
                    "--target-rmse {k}: met with r = {r} (every certified RMSE within {ratio:.3} \
                     times the observed)"
                )?;
            }
            break report;
        }
        if r == most {
            if !args.format.json() {
                writeln!(
                    out,
                    "--target-rmse {k}: not met with r = {r} = --max-sims (a certified RMSE is \
                     {ratio:.3} times the observed): raise --max-sims"
                )?;
            }
            break report;
        }
        r = r.saturating_mul(2).min(most);
    };
    if args.format.json() {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        writeln!(out, "{report}")?;
    }
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

/// The largest ratio of a certified RMSE to the observed one, over the
/// parameters and the whole vector (infinite when an observed error is 0,
/// since no finite r certifies a perfect estimator).
fn certified_ratio(report: &ValidationReport) -> f64 {
    let ratio = |bound: Option<f64>, observed_mse: f64| match bound {
        Some(mse_bound) if observed_mse > 0.0 => (mse_bound / observed_mse).sqrt(),
        _ => f64::INFINITY,
    };
    report
        .parameters
        .iter()
        .map(|p| ratio(p.certified.map(|c| c.upper()), p.mse))
        .chain([ratio(
            report.certified_total.map(|c| c.upper()),
            report.total.empirical_mse,
        )])
        .fold(0.0, f64::max)
}
