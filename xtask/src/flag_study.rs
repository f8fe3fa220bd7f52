//! Which flag knows when an estimate is far from what its record allows?
//! For an estimator and its family (a model file of
//! the built-in car), two candidate flags are calibrated on fresh records
//! of the family, each at 99% of them (split conformal), and set against
//! the exact posterior mean on the car's manoeuvres:
//!
//! - **the features' density**: the root mean square distance of a
//!   record's stage-1 features (standardized by the reference records'
//!   spread) to their nearest reference records', as the input shape's
//!   flag does with autocorrelations;
//! - **the ensemble's disagreement**: the spread of stage 2's averaged
//!   networks' outputs (standardized parameters), where an ensemble was
//!   trained.
//!
//! For each manoeuvre: the share each flags, and the estimator's pK1 error
//! over the Bayes posterior mean's on the records neither flags.

use anyhow::Result;
use rayon::prelude::*;
use twostage::Estimator;
use twostage::compress::Compressor;
use twostage::fit::FittedRegressor;
use twostage::models::IoData;
use twostage_kernels::input_shape::{NEIGHBOURS, nearest_distance};
use twostage_kernels::layer::{Activation, dense_layer};

use crate::bayes_gap::{CarManoeuvre, Steering, car_manoeuvre, rmse};
use crate::learned_summary::Family;
use crate::paper::test_records;

/// The options of `xtask flag-study`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The family and its estimator.
    #[command(flatten)]
    of: Family,
    /// Fresh family records: half the reference, half the calibration.
    #[arg(long, default_value_t = 4096)]
    family: usize,
    /// Test records per manoeuvre (10,000 reuse `bayes-gap`'s posteriors).
    #[arg(long, default_value_t = 10000)]
    records: usize,
    /// The manoeuvres, comma separated.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "chicane,iso3888,sine-with-dwell,step-steer,slalom,ramp-hold,random"
    )]
    steerings: Vec<Steering>,
}

/// The share of the family's own records a flag lets pass.
const LEVEL: f64 = 0.99;

/// The split-conformal threshold: the ceil((n + 1) LEVEL)-th smallest score.
fn threshold(mut scores: Vec<f64>) -> f64 {
    scores.sort_by(f64::total_cmp);
    let n = scores.len();
    let rank = (((n + 1) as f64) * LEVEL).ceil() as usize;
    scores
        .get(rank.saturating_sub(1))
        .copied()
        .unwrap_or(f64::INFINITY)
}

fn features(estimator: &Estimator, records: &[IoData]) -> Result<Vec<Vec<f64>>> {
    let compressor = estimator.compressor();
    Ok(records
        .par_iter()
        .map(|r| compressor.compress(r.inputs(), r.outputs()))
        .collect::<Result<_, _>>()?)
}

/// Columns' mean and spread over `rows`.
fn spread(rows: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let width = rows.first().map_or(0, Vec::len);
    let n = rows.len().max(1) as f64;
    let mean: Vec<f64> = (0..width)
        .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n)
        .collect();
    let sd = (0..width)
        .map(|j| {
            let v = rows.iter().map(|r| (r[j] - mean[j]).powi(2)).sum::<f64>() / n;
            v.sqrt().max(1e-12)
        })
        .collect();
    (mean, sd)
}

struct Density {
    mean: Vec<f64>,
    sd: Vec<f64>,
    reference: Vec<f64>,
}

impl Density {
    fn new(rows: &[Vec<f64>]) -> Self {
        let (mean, sd) = spread(rows);
        let mut d = Self {
            mean,
            sd,
            reference: Vec::new(),
        };
        d.reference = rows.iter().flat_map(|r| d.standard(r)).collect();
        d
    }
    fn standard(&self, row: &[f64]) -> Vec<f64> {
        row.iter()
            .zip(self.mean.iter().zip(&self.sd))
            .map(|(v, (m, s))| (v - m) / s)
            .collect()
    }
    fn distance(&self, row: &[f64]) -> f64 {
        let mut nearest = [0.0; NEIGHBOURS];
        nearest_distance(&self.reference, &self.standard(row), None, &mut nearest)
    }
}

/// The spread of the ensemble's members' outputs on `row`, in standardized
/// parameters: the root mean square over parameters of each one's
/// standard deviation across members.
fn disagreement(regressor: &FittedRegressor, row: &[f64]) -> Option<f64> {
    let FittedRegressor::Mlp(net) = regressor else {
        return None;
    };
    if net.n_members() < 2 {
        return None;
    }
    let mut x = vec![0.0; row.len()];
    net.feature_scaling().transform_into(row, &mut x);
    let sizes = net.sizes();
    let outputs: Vec<Vec<f64>> = net
        .members()
        .iter()
        .map(|params| {
            let mut input = x.clone();
            let mut p = 0;
            for (l, w) in sizes.windows(2).enumerate() {
                let (n_in, n_out) = (w[0], w[1]);
                let mut out = vec![0.0; n_out];
                let activation = if l + 2 < sizes.len() {
                    Activation::Tanh
                } else {
                    Activation::Identity
                };
                dense_layer(
                    &params[p..p + n_out * n_in],
                    &params[p + n_out * n_in..p + n_out * (n_in + 1)],
                    &input,
                    activation,
                    &mut out,
                );
                p += n_out * (n_in + 1);
                input = out;
            }
            input
        })
        .collect();
    let members = outputs.len() as f64;
    let q = outputs[0].len();
    let variance: f64 = (0..q)
        .map(|j| {
            let mean = outputs.iter().map(|o| o[j]).sum::<f64>() / members;
            outputs.iter().map(|o| (o[j] - mean).powi(2)).sum::<f64>() / (members - 1.0)
        })
        .sum::<f64>()
        / q as f64;
    Some(variance.sqrt())
}

pub(crate) fn run(c: &Args) -> Result<()> {
    let (estimator, family) = c.of.open()?;
    let (_, fresh) = test_records(family.as_ref(), 2 * c.family, 7)?;
    let compressor = estimator.compressor();
    let fresh: Vec<IoData> = fresh
        .into_iter()
        .filter(|r| compressor.compress(r.inputs(), r.outputs()).is_ok())
        .collect();
    let rows = features(&estimator, &fresh)?;
    let third = rows.len() / 3;
    let (reference, rest) = rows.split_at(third);
    let (calibration, own) = rest.split_at(third);
    let density = Density::new(reference);
    let regressor = estimator.regressor();
    let density_threshold = threshold(
        calibration
            .par_iter()
            .map(|r| density.distance(r))
            .collect(),
    );
    let spread_scores: Option<Vec<f64>> = calibration
        .par_iter()
        .map(|r| disagreement(regressor, r))
        .collect();
    let spread_threshold = spread_scores.map(threshold);
    let flags = |rows: &[Vec<f64>]| -> Vec<(bool, bool)> {
        rows.par_iter()
            .map(|r| {
                let far = density.distance(r) > density_threshold;
                let split = match (spread_threshold, disagreement(regressor, r)) {
                    (Some(t), Some(d)) => d > t,
                    _ => false,
                };
                (far, split)
            })
            .collect()
    };
    let share = |f: &[(bool, bool)], pick: fn(&(bool, bool)) -> bool| {
        f.iter().filter(|x| pick(x)).count() as f64 / f.len().max(1) as f64
    };
    let own_flags = flags(own);
    println!(
        "{}: {} reference and {} calibration records of the family; thresholds: features' \
         density {density_threshold:.3}, ensemble's disagreement {}",
        c.of.estimator.display(),
        reference.len(),
        calibration.len(),
        spread_threshold.map_or("(no ensemble)".into(), |t| format!("{t:.4}"))
    );
    println!(
        "  the family's other {} records: density flags {:.3}, disagreement {:.3}, either {:.3}",
        own.len(),
        share(&own_flags, |x| x.0),
        share(&own_flags, |x| x.1),
        share(&own_flags, |x| x.0 || x.1)
    );
    for &steering in &c.steerings {
        let CarManoeuvre {
            truth,
            records,
            posterior,
            ..
        } = car_manoeuvre(steering, c.records)?;
        let estimates: Vec<Vec<f64>> = records
            .par_iter()
            .map(|r| estimator.estimate_record(r))
            .collect::<Result<_, _>>()?;
        let f = flags(&features(&estimator, &records)?);
        let ratio = |rows: &[usize]| {
            if rows.is_empty() {
                f64::NAN
            } else {
                rmse(&estimates, &truth, 0, rows) / rmse(&posterior, &truth, 0, rows)
            }
        };
        let all: Vec<usize> = (0..records.len()).collect();
        let passed: Vec<usize> = all
            .iter()
            .copied()
            .filter(|&i| !(f[i].0 || f[i].1))
            .collect();
        println!(
            "  {steering:?}: pK1 ratio {:.3}; density flags {:.3}, disagreement {:.3}, either \
             {:.3}; pK1 ratio on the {} records neither flags {:.3}",
            ratio(&all),
            share(&f, |x| x.0),
            share(&f, |x| x.1),
            share(&f, |x| x.0 || x.1),
            passed.len(),
            ratio(&passed)
        );
    }
    Ok(())
}
