//! `twostage demo`: the main job of a new user, end to end in seconds.

use std::io::Write;
use std::time::Instant;

use crate::OrUsage;
use anyhow::{Context, Result};
use twostage::models::{Benchmark, Simulator, experiment_rng};
use twostage::{EstimateWorkspace, RunSettings, TwoStage};

/// Options of `twostage demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Seed of the training run.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The true theta of the fresh record estimated at the end.
    #[arg(long, default_value_t = 0.5, allow_hyphen_values = true)]
    theta: f64,
}

/// Train the paper's benchmark preset, validate it on fresh simulations,
/// and estimate theta from a record it has never seen.
pub fn demo(args: &DemoArgs, out: &mut dyn Write) -> Result<()> {
    let model = Benchmark::new();
    model
        .prior()
        .check(&[args.theta], model.param_names(), false)
        .usage_context("--theta")?;
    writeln!(
        out,
        "Training the two-stage estimator of the paper's benchmark (eq. 5):\n  \
         1500 simulations, ARX(5, 5) compression, a 10-unit network (Section 5.3)."
    )?;
    let start = Instant::now();
    let bars = crate::bars::Bars::new(false);
    let estimator = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .seed(args.seed)
        .calibration(1000)
        .progress(&bars)
        .train()
        .context("training the benchmark preset")?;
    // The default validation: grown until its certificate is within a
    // multiple of the error seen.
    let validated = estimator
        .validation()
        .map_or(0, |report| report.total.r as usize);
    let within = RunSettings::default()
        .certify_within
        .unwrap_or(f64::INFINITY);
    writeln!(
        out,
        "Trained on 1500 simulations, calibrated on 1000 and validated on {validated} (as many \
         as it took to certify the RMSE within {within} times what was seen) in {:.2} s.\n",
        start.elapsed().as_secs_f64()
    )?;
    if let Some(report) = estimator.validation() {
        writeln!(out, "{report}\n")?;
    }
    let mut record = model.spec().new_record();
    model.simulate(&[args.theta], &mut experiment_rng(u64::MAX, 0), &mut record)?;
    let mut work = EstimateWorkspace::new();
    let mut theta = [0.0];
    estimator.estimate_into(record.inputs(), record.outputs(), &mut work, &mut theta)?;
    // Time many estimates of the same record: the cost of one, warm.
    let repeats = 2000;
    let timer = Instant::now();
    for _ in 0..repeats {
        estimator.estimate_into(record.inputs(), record.outputs(), &mut work, &mut theta)?;
    }
    let micros = timer.elapsed().as_secs_f64() * 1e6 / repeats as f64;
    write!(
        out,
        "A fresh record of N = 1000 samples simulated at theta = {}: estimated theta = {:.4}",
        args.theta, theta[0]
    )?;
    let assessment = estimator.assess(&record)?;
    match (&assessment.adaptive_half_widths, estimator.intervals()) {
        (Some(w), _) => write!(out, " +- {:.4} (this record's 90% adaptive interval)", w[0])?,
        (None, Some(c)) => write!(
            out,
            " +- {:.4} (90% conformal interval)",
            c.half_widths()[0]
        )?,
        (None, None) => {}
    }
    writeln!(
        out,
        ",\nin {micros:.1} us per estimate (the paper's Matlab: 10 ms)."
    )?;
    if let (Some(d), Some(t)) = (assessment.feature_distance, assessment.distance_threshold) {
        writeln!(
            out,
            "Its features lie at Mahalanobis distance {d:.2} from the training features \
             ({}: out of distribution beyond {t:.2}).",
            if assessment.out_of_distribution() {
                "OUT OF DISTRIBUTION"
            } else {
                "in distribution"
            }
        )?;
    }
    Ok(())
}
