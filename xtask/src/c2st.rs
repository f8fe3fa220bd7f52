//! The classifier two-sample test of a posterior (sbibm's C2ST, Lueckmann
//! et al. 2021): for each of a set of records, [`DRAWS`] draws from the
//! estimator's posterior and as many from the exact posterior, told apart
//! by an MLP of two layers of 10 units a parameter, by its accuracy under
//! 5-fold cross-validation (0.5: the two alike). A second set of exact
//! draws against the first gives the test's own floor on these records.

use std::time::Instant;

use anyhow::{Context, Result};
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use twostage::fit::{Classifier, MlpParams, two_sample_accuracy};
use twostage::models::{IoData, StreamPurpose, stream_rng};
use twostage::{EstimateWorkspace, Estimator};
use twostage_baselines::{BayesBenchmark, BayesCar};

/// Draws from each posterior, as sbibm takes.
pub(crate) const DRAWS: usize = 10_000;
/// Cross-validation folds, as sbibm takes.
const FOLDS: usize = 5;
/// Records whose test is repeated with exact draws on both sides.
const FLOOR_RECORDS: usize = 10;

/// Where the exact draws come from.
pub(crate) enum Reference {
    /// The benchmark's adaptive grid.
    Benchmark(BayesBenchmark),
    /// The car's grid, simulated on the records' steering.
    Car(Box<BayesCar>),
}

impl Reference {
    fn draws(&self, record: &IoData, rng: &mut ChaCha8Rng) -> Result<Array2<f64>> {
        Ok(match self {
            Self::Benchmark(bayes) => {
                Array2::from_shape_vec((DRAWS, 1), bayes.draws(record, DRAWS, rng)?)?
            }
            Self::Car(bayes) => {
                let draws = bayes.draws(record, DRAWS, BayesCar::DRAW_POINTS, rng)?;
                Array2::from_shape_fn((DRAWS, 2), |(i, j)| draws[i][j])
            }
        })
    }
}

/// The estimator's draws of record `index` (the stream `estimate
/// --samples` draws it from).
fn estimator_draws(
    estimator: &Estimator,
    record: &IoData,
    index: usize,
    seed: u64,
) -> Result<Array2<f64>> {
    let q = estimator.param_names().len();
    let mut draws = vec![0.0; DRAWS * q];
    let mut rng = stream_rng(seed, index as u64, StreamPurpose::Posterior);
    estimator.sample_into(
        record.inputs(),
        record.outputs(),
        &mut EstimateWorkspace::new(),
        &mut rng,
        &mut draws,
    )?;
    Ok(Array2::from_shape_vec((DRAWS, q), draws)?)
}

fn classifier(dim: usize, seed: u64) -> Result<Classifier> {
    let network = MlpParams::new(&[10 * dim, 10 * dim])?
        .restarts(1)
        .seed(seed)
        .check()?;
    Ok(Classifier::new(network)?)
}

/// Mean, lowest and highest of `values`, in words.
fn spread_words(values: &[f64]) -> String {
    let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
    let (low, high) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    format!("{mean:.3} (from {low:.3} to {high:.3})")
}

/// The test on the first `count` of `records`, printed.
pub(crate) fn run(
    estimator: &Estimator,
    reference: &Reference,
    records: &[IoData],
    count: usize,
    seed: u64,
) -> Result<()> {
    estimator
        .posterior()
        .context("the estimator has no posterior to test (train it with --posterior K)")?;
    let count = count.min(records.len());
    let q = estimator.param_names().len();
    let start = Instant::now();
    let scores: Vec<(f64, Option<f64>)> = records[..count]
        .par_iter()
        .enumerate()
        .map(|(i, record)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xc257);
            rng.set_stream(i as u64);
            let exact = reference.draws(record, &mut rng)?;
            let drawn = estimator_draws(estimator, record, i, seed)?;
            let tester = classifier(q, seed.wrapping_add(i as u64))?;
            let score = two_sample_accuracy(exact.view(), drawn.view(), FOLDS, &tester)?;
            let floor = if i < FLOOR_RECORDS {
                let again = reference.draws(record, &mut rng)?;
                Some(two_sample_accuracy(
                    exact.view(),
                    again.view(),
                    FOLDS,
                    &tester,
                )?)
            } else {
                None
            };
            Ok((score, floor))
        })
        .collect::<Result<_>>()?;
    let posterior: Vec<f64> = scores.iter().map(|s| s.0).collect();
    let floor: Vec<f64> = scores.iter().filter_map(|s| s.1).collect();
    println!(
        "  C2ST ({DRAWS} draws each, {FOLDS}-fold MLP [{h}, {h}]) on {count} records: the \
         posterior's draws against the exact posterior's {}; exact against exact on {} of them \
         {} ({:.0} s)",
        spread_words(&posterior),
        floor.len(),
        spread_words(&floor),
        start.elapsed().as_secs_f64(),
        h = 10 * q
    );
    Ok(())
}
