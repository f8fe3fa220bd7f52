//! How far an estimator of a built-in model sits from the Bayes limit: its
//! RMSE and the exact posterior mean's on the same fresh records, per
//! parameter (the limit moves from test set to test set, so only a shared
//! set gives a ratio worth quoting).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use twostage::models::BuiltinModel;
use twostage::{ClassicMethod, EstimateWorkspace, Estimator};
use twostage_baselines::{InitialCovariance, MethodSettings, classic_estimator};

use crate::paper::test_records;

pub(crate) fn run(path: &Path, count: usize, seed: u64) -> Result<()> {
    let estimator = Estimator::load(path)
        .with_context(|| format!("reading the estimator {}", path.display()))?;
    let Ok(kind) = estimator.training().model.parse::<BuiltinModel>() else {
        bail!(
            "{} was trained on {}; the exact Bayes references here are the built-in models' \
             (benchmark, pacejka)",
            path.display(),
            estimator.training().model
        );
    };
    let model = kind.build(false)?;
    let (truth, records) = test_records(model.as_ref(), count, seed)?;
    let settings = MethodSettings {
        initial_covariance: InitialCovariance::Eq6,
        particles: None,
        starts: 1,
        seed,
    };
    let bayes = classic_estimator(kind, ClassicMethod::Bayes, &settings)?;
    let q = estimator.param_names().len();
    let start = Instant::now();
    let ts: Vec<Vec<f64>> = records
        .par_iter()
        .map_init(EstimateWorkspace::new, |work, record| {
            let mut theta = vec![0.0; q];
            estimator
                .estimate_into(record.inputs(), record.outputs(), work, &mut theta)
                .map(|_| theta)
        })
        .collect::<Result<_, _>>()?;
    let ts_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let posterior: Vec<Vec<f64>> = records
        .par_iter()
        .map(|record| bayes.estimate(record).map(|e| e.theta))
        .collect::<Result<_, _>>()?;
    let bayes_seconds = start.elapsed().as_secs_f64();
    let rmse = |estimates: &[Vec<f64>], j: usize| {
        let sse: f64 = estimates
            .iter()
            .zip(&truth)
            .map(|(e, t)| (e[j] - t[j]).powi(2))
            .sum();
        (sse / count.max(1) as f64).sqrt()
    };
    println!(
        "{count} fresh {} records (seed {seed}): {} in {ts_seconds:.2} s, the Bayes posterior \
         mean in {bayes_seconds:.1} s",
        kind.name(),
        path.display()
    );
    for (j, name) in estimator.param_names().iter().enumerate() {
        let (ts_rmse, bayes_rmse) = (rmse(&ts, j), rmse(&posterior, j));
        println!(
            "  {name}: RMSE {ts_rmse:.5}, Bayes posterior mean RMSE {bayes_rmse:.5}; ratio {:.3}",
            ts_rmse / bayes_rmse
        );
    }
    Ok(())
}
