//! Does a stage 1 that learns read the car's records better than its
//! least-squares coefficients (issue 69)? A summary network is trained on
//! a family's records and parameters, stage 2 is fitted on its summary
//! alone and beside the family estimator's own features, and each is set
//! against the exact posterior mean on the manoeuvres of `bayes-gap`,
//! with the family estimator's features and the same stage 2 as the
//! reference.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ndarray::{Array2, Axis, concatenate};
use rayon::prelude::*;
use twostage::compress::{Compressor, LearnedShape, SummaryNetwork, Workspace};
use twostage::fit::{Predictor, SummaryTraining};
use twostage::models::{IoData, Simulator};
use twostage::{Estimator, ModelFile, RegressorConfig};

use crate::bayes_gap::{CarManoeuvre, Steering, bootstrap_ratio, car_manoeuvre, rmse};
use crate::paper::test_records;

/// What one run compares (the options of `xtask learned-summary`).
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The family and its estimator (whose stage 1 is the reference).
    #[command(flatten)]
    family: Family,
    /// Training records.
    #[arg(long, default_value_t = 8000)]
    sims: usize,
    /// Test records per manoeuvre.
    #[arg(long, default_value_t = 10000)]
    records: usize,
    /// Stage 2, as `train --fit` takes it.
    #[arg(long, default_value = "ensemble:10")]
    fit: String,
    /// Channels of each convolution, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "8,8,8")]
    channels: Vec<usize>,
    /// Kernel width of every convolution.
    #[arg(long, default_value_t = 5)]
    kernel: usize,
    /// Stride of every convolution.
    #[arg(long, default_value_t = 2)]
    stride: usize,
    /// Hidden units of the head trained with it.
    #[arg(long, default_value_t = 16)]
    head: usize,
    /// Most epochs.
    #[arg(long, default_value_t = 80)]
    epochs: usize,
    /// Adam's learning rate.
    #[arg(long, default_value_t = 3e-3)]
    learning_rate: f64,
    /// Epochs without a better held-out loss before stopping.
    #[arg(long, default_value_t = 15)]
    patience: usize,
    /// Records per mini-batch.
    #[arg(long, default_value_t = 32)]
    batch_size: usize,
    /// Seed of the training records and the network.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The manoeuvres, comma separated.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "chicane,iso3888,sine-with-dwell,step-steer,slalom,random"
    )]
    steerings: Vec<Steering>,
    /// Divide each record by its own inputs' RMS before the network (a
    /// linear system's record then looks the same at every amplitude),
    /// the logarithm of that RMS appended to the learned summary.
    #[arg(long)]
    scale_by_input: bool,
    /// Networks trained (seeds `seed`, `seed + 1`, ...), each with its own
    /// stage 2; the estimates of all are averaged beside the first's.
    #[arg(long, default_value_t = 1)]
    members: usize,
}

impl Args {
    /// The summary network's training these options ask for.
    fn training(&self) -> SummaryTraining {
        SummaryTraining {
            shape: LearnedShape {
                channels: self.channels.clone(),
                kernel: self.kernel,
                stride: self.stride,
            },
            head: self.head,
            epochs: self.epochs,
            learning_rate: self.learning_rate,
            patience: self.patience,
            batch_size: self.batch_size,
            seed: self.seed,
            ..SummaryTraining::default()
        }
    }
}

/// The root mean square of a record's inputs (of its outputs without
/// inputs), never below a floor that keeps a record at rest finite.
fn input_level(record: &IoData) -> f64 {
    let signal = if record.inputs().ncols() > 0 {
        record.inputs()
    } else {
        record.outputs()
    };
    let n = signal.len().max(1) as f64;
    (signal.iter().map(|v| v * v).sum::<f64>() / n)
        .sqrt()
        .max(1e-6)
}

/// `record` divided by its inputs' RMS when `by_input`.
fn rescaled(record: &IoData, by_input: bool) -> (Array2<f64>, Array2<f64>) {
    let level = if by_input { input_level(record) } else { 1.0 };
    (
        record.inputs().mapv(|v| v / level),
        record.outputs().mapv(|v| v / level),
    )
}

/// The family estimator's features of `records` (the records it cannot
/// compress, such as one that never steers, are an error: the caller
/// leaves them out with [`compressible`]).
fn features(estimator: &Estimator, records: &[IoData]) -> Result<Array2<f64>> {
    let compressor = estimator.compressor();
    let rows: Vec<Vec<f64>> = records
        .par_iter()
        .map(|r| compressor.compress(r.inputs(), r.outputs()))
        .collect::<Result<_, _>>()?;
    let width = compressor.n_features();
    Ok(Array2::from_shape_vec((rows.len(), width), rows.concat())?)
}

/// Estimates, a row per record.
type Rows = Vec<Vec<f64>>;

fn rows(a: &Array2<f64>) -> Rows {
    a.rows().into_iter().map(|r| r.to_vec()).collect()
}

fn table(truth: &[Vec<f64>]) -> Array2<f64> {
    let width = truth.first().map_or(0, Vec::len);
    Array2::from_shape_fn((truth.len(), width), |(i, j)| truth[i][j])
}

/// The records (and their parameters) the family estimator's stage 1 can
/// compress, and how many it cannot.
fn compressible(
    estimator: &Estimator,
    (truth, records): (Vec<Vec<f64>>, Vec<IoData>),
) -> (Vec<Vec<f64>>, Vec<IoData>, usize) {
    let compressor = estimator.compressor();
    let total = records.len();
    let (truth, records): (Vec<_>, Vec<_>) = truth
        .into_iter()
        .zip(records)
        .filter(|(_, r)| compressor.compress(r.inputs(), r.outputs()).is_ok())
        .unzip();
    let left = total - records.len();
    (truth, records, left)
}

/// The three stage-1 choices' features of `records`.
fn variants(
    estimator: &Estimator,
    network: &SummaryNetwork,
    records: &[IoData],
    by_input: bool,
) -> Result<[Array2<f64>; 3]> {
    let reference = features(estimator, records)?;
    let width = network.n_features() + usize::from(by_input);
    let rows: Vec<Vec<f64>> = records
        .par_iter()
        .map(|r| {
            let mut row = vec![0.0; network.n_features()];
            let (u, y) = rescaled(r, by_input);
            network.summarize(u.view(), y.view(), &mut Workspace::new(), &mut row)?;
            if by_input {
                row.push(input_level(r).ln());
            }
            Ok(row)
        })
        .collect::<Result<_>>()?;
    let learned = Array2::from_shape_vec((rows.len(), width), rows.concat())?;
    let both = concatenate(Axis(1), &[reference.view(), learned.view()])?;
    Ok([reference, learned, both])
}

const NAMES: [&str; 3] = ["features", "learned", "features+learned"];

/// A family of the built-in car and an estimator of it.
#[derive(Debug, clap::Args)]
pub(crate) struct Family {
    /// The family's model file (of the built-in car).
    #[arg(long)]
    pub model_file: PathBuf,
    /// An estimator of that family.
    #[arg(long)]
    pub estimator: PathBuf,
}

impl Family {
    /// The estimator and the family's simulator, refused unless the
    /// estimator was trained on the family's model.
    pub(crate) fn open(&self) -> Result<(Estimator, Box<dyn Simulator>)> {
        estimator_and_family(&self.estimator, &self.model_file)
    }
}

/// The estimator at `path` and the simulator of the family `model_file`
/// describes, refused unless the estimator was trained on that model.
fn estimator_and_family(path: &Path, model_file: &Path) -> Result<(Estimator, Box<dyn Simulator>)> {
    let estimator = Estimator::load(path).with_context(|| format!("reading {}", path.display()))?;
    let family = ModelFile::load(model_file)?.simulator()?;
    if family.spec().name() != estimator.training().model {
        bail!(
            "{} was trained on {}, not on {}",
            path.display(),
            estimator.training().model,
            family.spec().name()
        );
    }
    Ok((estimator, family))
}

pub(crate) fn run(c: &Args) -> Result<()> {
    let summary = c.training();
    let (estimator, family) = c.family.open()?;
    let start = Instant::now();
    let (truth, records, left) = compressible(
        &estimator,
        test_records(family.as_ref(), c.sims, summary.seed)?,
    );
    if left > 0 {
        println!("{left} training records left out: the reference stage 1 cannot compress them");
    }
    let simulated = start.elapsed().as_secs_f64();
    let recs: Vec<Array2<f64>> = records
        .par_iter()
        .map(|r| {
            let (u, y) = rescaled(r, c.scale_by_input);
            concatenate(Axis(1), &[u.view(), y.view()]).unwrap_or_default()
        })
        .collect();
    let y = table(&truth);
    let fit: RegressorConfig = c.fit.parse()?;
    let mut members = Vec::new();
    for member in 0..c.members.max(1) {
        let start = Instant::now();
        let training = SummaryTraining {
            seed: summary.seed + member as u64,
            ..summary.clone()
        };
        let trained = training.train(&recs, y.view())?;
        println!(
            "{} records of {} in {simulated:.1} s; summary network {:?} (kernel {}, stride {}, head {}, \
             seed {}) trained in {:.1} s: {} epochs, stopped by {:?}, held-out MSE {:.4} (standardized)",
            c.sims,
            family.spec().name(),
            training.shape.channels,
            training.shape.kernel,
            training.shape.stride,
            training.head,
            training.seed,
            start.elapsed().as_secs_f64(),
            trained.epochs,
            trained.reason,
            trained.held_out_mse
        );
        let history: Vec<String> = trained.history.iter().map(|v| format!("{v:.4}")).collect();
        println!("  held-out MSE by epoch: {}", history.join(" "));
        let x = variants(&estimator, &trained.network, &records, c.scale_by_input)?;
        let mut stage2 = Vec::new();
        for (name, x) in NAMES.iter().zip(&x) {
            let start = Instant::now();
            stage2.push(fit.fit(x.view(), y.view(), training.seed)?);
            println!(
                "  stage 2 on {name} ({} numbers) in {:.1} s",
                x.ncols(),
                start.elapsed().as_secs_f64()
            );
        }
        members.push((trained.network, stage2));
    }
    // Each variant's estimates of `records`: the first member's, and the
    // average of all members'.
    let estimates = |records: &[IoData]| -> Result<Vec<[Vec<Vec<f64>>; 2]>> {
        // Per variant: the first member's estimates and the sum of all.
        let mut sums: Vec<Option<(Rows, Rows)>> = vec![None, None, None];
        for (network, stage2) in &members {
            let x = variants(&estimator, network, records, c.scale_by_input)?;
            for (v, (x, f)) in x.iter().zip(stage2).enumerate() {
                let est = rows(&f.predict(x.view())?);
                match &mut sums[v] {
                    None => sums[v] = Some((est.clone(), est)),
                    Some((_, total)) => total
                        .iter_mut()
                        .flatten()
                        .zip(est.iter().flatten())
                        .for_each(|(a, b)| *a += b),
                }
            }
        }
        let k = members.len() as f64;
        Ok(sums
            .into_iter()
            .flatten()
            .map(|(first, total)| {
                let mean = total
                    .into_iter()
                    .map(|row| row.into_iter().map(|v| v / k).collect())
                    .collect();
                [first, mean]
            })
            .collect())
    };
    // The family's own fresh records: the stage-2 fits' held-out error.
    let (family_truth, family_records, _) = compressible(
        &estimator,
        test_records(family.as_ref(), c.records.min(2000), 2026)?,
    );
    let held = estimates(&family_records)?;
    let averaged = if members.len() > 1 { 2 } else { 1 };
    let (q, family_truth) = (y.ncols(), &family_truth);
    let words: Vec<String> = NAMES
        .iter()
        .zip(&held)
        .flat_map(|(name, both)| {
            both[..averaged].iter().enumerate().map(move |(a, est)| {
                let all: Vec<usize> = (0..est.len()).collect();
                format!(
                    "{name}{} {}",
                    if a == 0 { "" } else { " averaged" },
                    (0..q)
                        .map(|j| format!("{:.4}", rmse(est, family_truth, j, &all)))
                        .collect::<Vec<_>>()
                        .join("/")
                )
            })
        })
        .collect();
    println!(
        "  the family's fresh records, RMSE per parameter: {}",
        words.join(", ")
    );

    for &steering in &c.steerings {
        let CarManoeuvre {
            car,
            truth,
            records,
            posterior,
        } = car_manoeuvre(steering, c.records)?;
        let all: Vec<usize> = (0..records.len()).collect();
        let mut line = format!("  {steering:?}:");
        for (name, both) in NAMES.iter().zip(estimates(&records)?) {
            for (a, est) in both[..averaged].iter().enumerate() {
                // As the estimator does: an estimate outside the prior's
                // box is brought to its edge.
                let (lower, upper) = (car.prior().lower(), car.prior().upper());
                let est: Vec<Vec<f64>> = est
                    .iter()
                    .map(|t| {
                        t.iter()
                            .zip(lower.iter().zip(upper.iter()))
                            .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
                            .collect()
                    })
                    .collect();
                let name = if a == 0 {
                    name.to_string()
                } else {
                    format!("{name} averaged")
                };
                for j in 0..2 {
                    let ratio = rmse(&est, &truth, j, &all) / rmse(&posterior, &truth, j, &all);
                    let [low, high] = bootstrap_ratio(&est, &posterior, &truth, j, 2026);
                    line += &format!(" {name} p{j} {ratio:.3} [{low:.3}, {high:.3}];");
                }
            }
        }
        println!("{line}");
    }
    Ok(())
}
