//! The classifier two-sample test of a posterior (sbibm's C2ST, Lueckmann
//! et al. 2021): for each of a set of records, [`DRAWS`] draws from the
//! estimator's posterior and as many from the exact posterior, told apart
//! by an MLP of two layers of 10 units a parameter, by its accuracy under
//! 5-fold cross-validation (0.5: the two alike). A second set of exact
//! draws against the first gives the test's own floor on these records.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
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

/// An experiment's name and its draws (draws x parameters).
type Experiment = (String, Array2<f64>);

/// Draws read from a CSV as `twostage estimate --draws` writes them (an
/// `experiment` column, a `draw` column, one per parameter; an
/// `out_of_distribution` column is left out), by
/// experiment in the order they first appear, with the parameters' names.
fn read_draws(path: &Path) -> Result<(Vec<String>, Vec<Experiment>)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines().enumerate();
    let (_, header) = lines
        .next()
        .with_context(|| format!("{} is empty", path.display()))?;
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let experiment = columns
        .iter()
        .position(|c| *c == "experiment")
        .with_context(|| format!("{}: no `experiment` column in the header", path.display()))?;
    let parameters: Vec<usize> = (0..columns.len())
        .filter(|&j| j != experiment && !["draw", "out_of_distribution"].contains(&columns[j]))
        .collect();
    let names = parameters.iter().map(|&j| columns[j].to_string()).collect();
    let mut groups: Vec<(String, Vec<f64>)> = Vec::new();
    for (number, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != columns.len() {
            anyhow::bail!(
                "{} line {}: {} cells where the header has {}",
                path.display(),
                number + 1,
                cells.len(),
                columns.len()
            );
        }
        let key = cells[experiment];
        if groups.last().is_none_or(|(k, _)| k != key) {
            groups.push((key.to_string(), Vec::new()));
        }
        let values = &mut groups.last_mut().expect("pushed above").1;
        for &j in &parameters {
            values.push(cells[j].parse().with_context(|| {
                format!(
                    "{} line {}, column {}: `{}` is not a number",
                    path.display(),
                    number + 1,
                    columns[j],
                    cells[j]
                )
            })?);
        }
    }
    let q = parameters.len();
    let groups = groups
        .into_iter()
        .map(|(key, values)| Ok((key, Array2::from_shape_vec((values.len() / q, q), values)?)))
        .collect::<Result<_>>()?;
    Ok((names, groups))
}

/// The test between two files of draws (say a method's and a reference
/// posterior's), experiment by experiment: each experiment of `first`
/// against the same experiment of `second`, printed.
pub(crate) fn files(first: &Path, second: &Path, seed: u64) -> Result<()> {
    let (names, ours) = read_draws(first)?;
    let (their_names, theirs) = read_draws(second)?;
    if names != their_names {
        anyhow::bail!(
            "{} draws {names:?} but {} draws {their_names:?}: the same parameters in the same \
             order are needed",
            first.display(),
            second.display()
        );
    }
    let start = Instant::now();
    let scores: Vec<(String, f64)> = ours
        .par_iter()
        .enumerate()
        .map(|(i, (key, drawn))| {
            let (_, exact) = theirs.iter().find(|(k, _)| k == key).with_context(|| {
                format!("{} has no draws of experiment {key}", second.display())
            })?;
            let tester = classifier(names.len(), seed.wrapping_add(i as u64))?;
            Ok((
                key.clone(),
                two_sample_accuracy(exact.view(), drawn.view(), FOLDS, &tester)?,
            ))
        })
        .collect::<Result<_>>()?;
    for (key, score) in &scores {
        println!("  experiment {key}: {score:.3}");
    }
    let values: Vec<f64> = scores.iter().map(|s| s.1).collect();
    println!(
        "  C2ST ({FOLDS}-fold MLP [{h}, {h}]) on {} experiments: {} ({:.0} s)",
        values.len(),
        spread_words(&values),
        start.elapsed().as_secs_f64(),
        h = 10 * names.len()
    );
    Ok(())
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
    (count, drawn_file): (usize, Option<&Path>),
    seed: u64,
) -> Result<()> {
    let count = count.min(records.len());
    let q = estimator.param_names().len();
    let from_file = match drawn_file {
        Some(path) => {
            let (names, experiments) = read_draws(path)?;
            if names != estimator.param_names() {
                bail!(
                    "{} draws {names:?}, the estimator estimates {:?}",
                    path.display(),
                    estimator.param_names()
                );
            }
            if experiments.len() < count {
                bail!(
                    "{} holds {} experiments: fewer than the {count} records to test",
                    path.display(),
                    experiments.len()
                );
            }
            Some(experiments)
        }
        None => {
            estimator
                .posterior()
                .context("the estimator has no posterior to test (train it with --posterior K)")?;
            None
        }
    };
    let start = Instant::now();
    let scores: Vec<(f64, Option<f64>)> = records[..count]
        .par_iter()
        .enumerate()
        .map(|(i, record)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xc257);
            rng.set_stream(i as u64);
            let exact = reference.draws(record, &mut rng)?;
            let drawn = match &from_file {
                Some(experiments) => experiments[i].1.clone(),
                None => estimator_draws(estimator, record, i, seed)?,
            };
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
