//! A network trained by a likelihood: the output layer is the head of a
//! distribution of each row's target (a mixture of Gaussians for the
//! density, a Bernoulli for the classifier), the loss the mean negative
//! log-likelihood plus weight decay, minimized by L-BFGS restarts that
//! keep the weights of the lowest held-out loss.
//!
//! Blocks of rows and the order their sums are added in are fixed: the
//! same bits on any thread count.

use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{FitError, Result};
use crate::levenberg_marquardt::TerminationReason;
use crate::standardize::Standardizer;

use super::held_out::BestHeldOut;
use super::lbfgs::{Objective, PATIENCE_SCALE, minimize};
use super::network::{
    BLOCK_SAMPLES, MAX_WIDTH, add_sample_gradient, by_columns, forward, gradient_by_blocks,
    initial_parameters, run_network, widest_vectors,
};
use super::params::MlpParams;
use super::training::{held_out_split, restart_rng};

/// One restart of a network trained by its likelihood (a mixture density
/// or a classifier).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DensityRestart {
    /// Restart index.
    pub restart: usize,
    /// L-BFGS iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub reason: TerminationReason,
    /// Mean negative log-likelihood of the training rows at the kept
    /// weights (the density's over standardized unbounded parameters).
    pub train_nll: f64,
    /// The same on the held-out rows (the training rows' when none are
    /// held out).
    pub held_out_nll: f64,
}

/// The distribution a network's output layer gives a row's target.
pub(super) trait Head: Sync {
    /// `−log p(target)` under the distribution `head` gives.
    fn nll(&self, head: &[f64], target: &[f64]) -> f64;
    /// `scale` times the derivative of [`Head::nll`] by each of the head's
    /// entries, into `delta`'s first entries.
    fn gradient(&self, head: &[f64], target: &[f64], scale: f64, delta: &mut [f64]);
}

/// The output layer of the network of layers `sizes` and weights
/// `params` given `x`, standardized by `features`: the head a likelihood
/// reads. `reader` names the network in an error.
pub(super) fn head_of(
    features: &Standardizer,
    (sizes, params): (&[usize], &[f64]),
    x: &[f64],
    reader: &str,
) -> Result<[f64; MAX_WIDTH]> {
    if x.len() != sizes[0] {
        return Err(FitError::ShapeMismatch(format!(
            "{} features given, {reader} reads {}",
            x.len(),
            sizes[0]
        )));
    }
    if let Some(bad) = x.iter().position(|v| !v.is_finite()) {
        return Err(FitError::NonFinite {
            what: "features",
            row: 0,
            col: bad,
            value: x[bad],
        });
    }
    let mut input = [0.0f64; MAX_WIDTH];
    features.transform_into(x, &mut input[..sizes[0]]);
    let mut head = [0.0f64; MAX_WIDTH];
    run_network(sizes, params, &input, &mut head);
    Ok(head)
}

/// A network of `p`'s hidden layers and `outputs` outputs read by `head`,
/// fitted to the targets `z` given the inputs `x` (standard-layout rows,
/// already standardized): rows held out as `p` says, restarts as
/// [`Likelihood::train`] runs them. Its layer sizes, the kept weights,
/// every restart's report and which was kept.
pub(super) fn fit_network<H: Head>(
    head: H,
    outputs: usize,
    (x, z): (&Array2<f64>, &Array2<f64>),
    p: &MlpParams,
    iterations: usize,
) -> Result<Fitted> {
    let (order, n_held) = held_out_split(x.nrows(), p)?;
    let (held_out, train) = order.split_at(n_held);
    let (sizes, offsets) = layers(x.ncols(), &p.hidden, outputs);
    let likelihood = Likelihood {
        sizes: &sizes,
        offsets,
        head,
        x,
        z,
        train,
        held_out: if held_out.is_empty() { train } else { held_out },
        decay: p.weight_decay,
    };
    let (params, reports, best) = likelihood.train(p, iterations, !held_out.is_empty());
    Ok((sizes, params, reports, best))
}

/// A fitted network: layer sizes, weights, every restart's report, the
/// restart kept.
pub(super) type Fitted = (Vec<usize>, Vec<f64>, Vec<DensityRestart>, usize);

/// Layer sizes (input, `hidden`, then the head's `outputs`) and where each
/// layer's activations start.
pub(super) fn layers(inputs: usize, hidden: &[usize], outputs: usize) -> (Vec<usize>, Vec<usize>) {
    let mut sizes = vec![inputs];
    sizes.extend(hidden);
    sizes.push(outputs);
    let mut offsets = vec![0];
    for s in &sizes {
        offsets.push(offsets.last().copied().unwrap_or(0) + s);
    }
    (sizes, offsets)
}

/// The training's loss: the mean negative log-likelihood of the targets
/// `z` given the inputs `x` (standard-layout rows), plus weight decay.
pub(super) struct Likelihood<'a, H> {
    pub(super) sizes: &'a [usize],
    pub(super) offsets: Vec<usize>,
    pub(super) head: H,
    pub(super) x: &'a Array2<f64>,
    pub(super) z: &'a Array2<f64>,
    pub(super) train: &'a [usize],
    pub(super) held_out: &'a [usize],
    pub(super) decay: f64,
}

impl<H: Head> Likelihood<'_, H> {
    fn activations(&self) -> Vec<f64> {
        vec![0.0; self.offsets.last().copied().unwrap_or(0)]
    }

    /// Row `i` of standard-layout `data`, one contiguous slice.
    fn row(data: &Array2<f64>, i: usize) -> &[f64] {
        data.row(i).to_slice().unwrap_or(&[])
    }

    /// Mean negative log-likelihood over `rows`: blocks in parallel, their
    /// sums added in block order.
    pub(super) fn mean_nll(&self, params: &[f64], rows: &[usize]) -> f64 {
        let columns = by_columns(self.sizes, params);
        let sum_block = |block: &[usize], acts: &mut Vec<f64>| -> f64 {
            let out = self.offsets[self.sizes.len() - 1];
            block
                .iter()
                .map(|&i| {
                    forward(
                        self.sizes,
                        &columns,
                        Self::row(self.x, i),
                        acts,
                        &self.offsets,
                    );
                    self.head.nll(&acts[out..], Self::row(self.z, i))
                })
                .sum()
        };
        let partials: Vec<f64> = rows
            .par_chunks(BLOCK_SAMPLES)
            .map_init(|| self.activations(), |acts, block| sum_block(block, acts))
            .collect();
        partials.iter().sum::<f64>() / rows.len().max(1) as f64
    }

    /// Add `scale` times the gradient of `rows`' negative log-likelihoods.
    fn add_gradient(
        &self,
        (params, columns): (&[f64], &[f64]),
        rows: &[usize],
        scale: f64,
        grad: &mut [f64],
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        let out = self.offsets[self.sizes.len() - 1];
        for &i in rows {
            forward(
                self.sizes,
                columns,
                Self::row(self.x, i),
                acts,
                &self.offsets,
            );
            self.head
                .gradient(&acts[out..], Self::row(self.z, i), scale, delta);
            add_sample_gradient(self.sizes, &self.offsets, params, acts, delta, grad);
        }
    }

    /// Restarts from `p`'s seeded weights, in parallel, each by L-BFGS for
    /// at most `iterations`: the weights of the restart with the lowest
    /// held-out loss (ties to the lower restart, so the choice does not
    /// depend on scheduling), every restart's report, and which was kept.
    /// `watched` says whether rows are held out to stop by.
    pub(super) fn train(
        &self,
        p: &MlpParams,
        iterations: usize,
        watched: bool,
    ) -> (Vec<f64>, Vec<DensityRestart>, usize) {
        let runs: Vec<(Vec<f64>, DensityRestart)> = (0..p.restarts)
            .into_par_iter()
            .map(|restart| {
                let params = initial_parameters(self.sizes, &mut restart_rng(p, restart));
                let held = self.held_out(&params);
                let mut best = BestHeldOut::new(
                    held,
                    &params,
                    p.patience.saturating_mul(PATIENCE_SCALE),
                    watched,
                );
                let (iterations, reason) = minimize(self, params, iterations, &mut best, p.stop_by);
                let (held_out_nll, params) = best.into_best();
                let report = DensityRestart {
                    restart,
                    iterations,
                    reason,
                    train_nll: self.mean_nll(&params, self.train),
                    held_out_nll,
                };
                (params, report)
            })
            .collect();
        let best = runs
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.1.held_out_nll.total_cmp(&b.1.1.held_out_nll))
            .map_or(0, |(i, _)| i);
        let (reports, mut params): (Vec<_>, Vec<_>) = runs.into_iter().map(|(w, r)| (r, w)).unzip();
        (std::mem::take(&mut params[best]), reports, best)
    }
}

impl<H: Head> Objective for Likelihood<'_, H> {
    fn loss(&self, params: &[f64]) -> f64 {
        let penalty = self.decay * params.iter().map(|v| v * v).sum::<f64>();
        self.mean_nll(params, self.train) + penalty / self.train.len().max(1) as f64
    }

    fn gradient(&self, params: &[f64], grad: &mut [f64]) {
        let rows = self.train;
        let scale = 1.0 / rows.len().max(1) as f64;
        let columns = by_columns(self.sizes, params);
        let weights = (params, columns.as_slice());
        gradient_by_blocks(
            rows,
            grad,
            self.offsets.last().copied().unwrap_or(0),
            |block, grad, acts, delta| {
                widest_vectors(|| self.add_gradient(weights, block, scale, grad, acts, delta));
            },
        );
        let decay = 2.0 * self.decay / rows.len().max(1) as f64;
        for (g, p) in grad.iter_mut().zip(params) {
            *g += decay * p;
        }
    }

    fn held_out(&self, params: &[f64]) -> f64 {
        self.mean_nll(params, self.held_out)
    }
}
