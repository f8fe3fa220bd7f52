//! How far an estimator of the benchmark sits from the Bayes limit: its
//! RMSE and the exact posterior mean's on the same fresh records (the
//! limit moves from test set to test set, so only a shared set gives a
//! ratio worth quoting).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use twostage::models::{Benchmark, BuiltinModel};
use twostage::{ClassicMethod, EstimateWorkspace, Estimator};
use twostage_baselines::{InitialCovariance, MethodSettings, classic_estimator};

use crate::paper::test_records;

pub(crate) fn run(path: &Path, count: usize, seed: u64) -> Result<()> {
    let estimator = Estimator::load(path)
        .with_context(|| format!("reading the estimator {}", path.display()))?;
    if estimator.training().model != BuiltinModel::Benchmark.name() {
        bail!(
            "{} was trained on {}; the exact Bayes reference here is the benchmark's: train \
             one with --model benchmark",
            path.display(),
            estimator.training().model
        );
    }
    let model = Benchmark::new();
    let (truth, records) = test_records(&model, count, seed)?;
    let settings = MethodSettings {
        initial_covariance: InitialCovariance::Eq6,
        particles: None,
        starts: 1,
        seed,
    };
    let bayes = classic_estimator(BuiltinModel::Benchmark, ClassicMethod::Bayes, &settings)?;
    let start = Instant::now();
    let ts: Vec<f64> = records
        .par_iter()
        .map_init(EstimateWorkspace::new, |work, record| {
            let mut theta = [0.0];
            estimator
                .estimate_into(record.inputs(), record.outputs(), work, &mut theta)
                .map(|_| theta[0])
        })
        .collect::<Result<_, _>>()?;
    let ts_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let posterior: Vec<f64> = records
        .par_iter()
        .map(|record| bayes.estimate(record).map(|e| e.theta[0]))
        .collect::<Result<_, _>>()?;
    let bayes_seconds = start.elapsed().as_secs_f64();
    let rmse = |estimates: &[f64]| {
        let sse: f64 = estimates
            .iter()
            .zip(&truth)
            .map(|(e, t)| (e - t[0]).powi(2))
            .sum();
        (sse / count.max(1) as f64).sqrt()
    };
    let (ts_rmse, bayes_rmse) = (rmse(&ts), rmse(&posterior));
    println!(
        "{count} fresh benchmark records (seed {seed}): {} RMSE {ts_rmse:.5} ({ts_seconds:.2} s), \
         Bayes posterior mean RMSE {bayes_rmse:.5} ({bayes_seconds:.1} s); ratio {:.3}",
        path.display(),
        ts_rmse / bayes_rmse
    );
    Ok(())
}
