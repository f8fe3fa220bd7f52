//! The network itself: layer sizes and weights, the forward pass (the
//! kernels' dense layer), back-propagation of residuals and of the
//! Jacobian, and the trained [`FittedMlp`] that predicts.

use ndarray::Array2;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use twostage_kernels::layer::{Activation, dense_layer};

use crate::Predictor;
use crate::TerminationReason;
use crate::check;
use crate::error::Result;
use crate::standardize::Standardizer;

/// How one restart went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RestartReport {
    /// Restart index.
    pub restart: usize,
    /// Iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub reason: TerminationReason,
    /// Training mean squared error (standardized targets) at the kept weights.
    pub train_mse: f64,
    /// Held-out mean squared error (standardized targets) at the kept weights
    /// (the training MSE when nothing is held out).
    pub validation_mse: f64,
}

/// The widest layer supported: prediction keeps activations on the stack.
pub const MAX_WIDTH: usize = 256;

/// The network of layer `sizes` and weights `params` (layer after layer:
/// W row-major, out x in, then b) on the standardized `input` (its first
/// `sizes[0]` entries): the output layer into `output`'s first entries, by
/// the estimate path's [`dense_layer`].
pub(super) fn run_network(
    sizes: &[usize],
    params: &[f64],
    input: &[f64; MAX_WIDTH],
    output: &mut [f64; MAX_WIDTH],
) {
    // Two stack buffers, used in turn as input and output of each layer.
    let mut a = *input;
    let mut b = [0.0f64; MAX_WIDTH];
    let layers = sizes.len() - 1;
    let mut p = 0;
    for l in 0..layers {
        let (n_in, n_out) = (sizes[l], sizes[l + 1]);
        let w = &params[p..p + n_out * n_in];
        let bias = &params[p + n_out * n_in..p + n_out * (n_in + 1)];
        dense_layer(w, bias, &a[..n_in], activation(l, layers), &mut b[..n_out]);
        std::mem::swap(&mut a, &mut b);
        p += n_out * (n_in + 1);
    }
    *output = a;
}

/// A trained network, with its standardization and training report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "super::stored::FittedMlpFields")]
pub struct FittedMlp {
    pub(super) features: Standardizer,
    pub(super) targets: Standardizer,
    /// Layer sizes, input first: `[n_in, hidden.., n_out]`.
    pub(super) sizes: Vec<usize>,
    /// The networks whose outputs are averaged, each with all its weights
    /// and biases, layer after layer: W (row-major, out x in) then b.
    pub(super) members: Vec<Vec<f64>>,
    /// One report per restart; `best` indexes the one kept.
    pub(super) reports: Vec<RestartReport>,
    pub(super) best: usize,
}

impl FittedMlp {
    /// The restarts' reports.
    pub fn reports(&self) -> &[RestartReport] {
        &self.reports
    }
    /// The restart whose weights were kept.
    pub fn best_restart(&self) -> &RestartReport {
        &self.reports[self.best]
    }
    /// How the kept network was trained, in words: "Levenberg-Marquardt,
    /// stopped by Converged (best of 4 restarts by Levenberg-Marquardt)",
    /// naming every trainer that ran (both when [`crate::Trainer::Auto`]
    /// ran Levenberg-Marquardt and Adam), and
    /// "average of" for an ensemble.
    pub fn training_summary(&self) -> String {
        let best = self.best_restart();
        let counts: Vec<String> = ["Levenberg-Marquardt", "Adam", "L-BFGS"]
            .iter()
            .filter_map(|&trainer| {
                let n = self
                    .reports
                    .iter()
                    .filter(|r| r.reason.trainer() == trainer)
                    .count();
                (n > 0).then(|| format!("{n} by {trainer}"))
            })
            .collect();
        let restarts = match counts.split_first() {
            Some((first, rest)) => {
                let mut said = first.replacen(" by ", " restarts by ", 1);
                for more in rest {
                    said.push_str(", ");
                    said.push_str(more);
                }
                said
            }
            None => "no restarts".to_string(),
        };
        let kept = match self.members.len() {
            1 => format!("best of {restarts}"),
            // An ensemble keeps them all: the stop named is its best's.
            _ => format!("average of {restarts}; the stop is the best restart's"),
        };
        format!(
            "{}, stopped by {} ({kept})",
            best.reason.trainer(),
            best.reason.name()
        )
    }

    /// Layer sizes, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }
    /// Number of weights and biases of one network.
    pub fn n_parameters(&self) -> usize {
        parameter_count(&self.sizes)
    }
    /// Number of networks averaged (1 unless trained as an ensemble).
    pub fn n_members(&self) -> usize {
        self.members.len()
    }
    /// Each member's weights and biases, layer by layer: row-major
    /// weights (row i feeds unit i), then the biases.
    pub fn members(&self) -> &[Vec<f64>] {
        &self.members
    }
    /// The standardization of the inputs.
    pub fn feature_scaling(&self) -> &Standardizer {
        &self.features
    }
    /// The standardization of the outputs (undone after the network).
    pub fn target_scaling(&self) -> &Standardizer {
        &self.targets
    }
}

/// Number of parameters of a network with these layer sizes.
pub(super) fn parameter_count(sizes: &[usize]) -> usize {
    sizes.windows(2).map(|w| w[1] * (w[0] + 1)).sum()
}

/// Every layer's weights transposed in place (column `c`, the weights from
/// input `c` to each unit, contiguous), biases as they are: the layout in
/// which [`forward`] adds one input's contribution to a whole layer at a
/// time.
pub(super) fn by_columns(sizes: &[usize], params: &[f64]) -> Vec<f64> {
    let mut columns = params.to_vec();
    let mut p = 0;
    for w in sizes.windows(2) {
        let (n_in, n_out) = (w[0], w[1]);
        for a in 0..n_out {
            for c in 0..n_in {
                columns[p + c * n_out + a] = params[p + a * n_in + c];
            }
        }
        p += n_out * (n_in + 1);
    }
    columns
}

/// Forward pass on standardized input `x`, keeping every layer's activation
/// in `acts` (layer l starts at `offsets[l]`); returns nothing, the output
/// is the last layer. `columns` are the weights [`by_columns`].
///
/// Each unit's sum takes the same additions in the same order as the
/// estimate path's [`dense_layer`] (from -0.0, input by input, the bias
/// last), so training and estimating give the same bits; the loop runs over
/// the units, whose sums are independent, and the processor overlaps them
/// where one dot product at a time waits on each addition. Inlined so that
/// the callers' [`widest_vectors`] reach its loops.
#[inline(always)]
pub(super) fn forward(
    sizes: &[usize],
    columns: &[f64],
    x: &[f64],
    acts: &mut [f64],
    offsets: &[usize],
) {
    acts[..sizes[0]].copy_from_slice(x);
    let mut p = 0;
    let layers = sizes.len() - 1;
    for l in 0..layers {
        let (n_in, n_out) = (sizes[l], sizes[l + 1]);
        let (before, after) = acts.split_at_mut(offsets[l + 1]);
        let input = &before[offsets[l]..offsets[l] + n_in];
        let out = &mut after[..n_out];
        out.fill(-0.0);
        for (column, &x) in columns[p..p + n_out * n_in].chunks_exact(n_out).zip(input) {
            for (o, w) in out.iter_mut().zip(column) {
                *o += w * x;
            }
        }
        let bias = &columns[p + n_out * n_in..p + n_out * (n_in + 1)];
        let tanh = activation(l, layers) == Activation::Tanh;
        for (o, b) in out.iter_mut().zip(bias) {
            let z = b + *o;
            *o = if tanh { twostage_kernels::tanh(z) } else { z };
        }
        p += n_out * (n_in + 1);
    }
}

/// Hidden layers are tanh, the output layer linear.
pub(super) fn activation(layer: usize, layers: usize) -> Activation {
    if layer + 1 < layers {
        Activation::Tanh
    } else {
        Activation::Identity
    }
}

/// One backward step through a tanh layer: `delta_{l-1} = (W_l' delta_l)
/// .* (1 - a^2)`, with `a` the layer's input activations. `delta` holds
/// `delta_l` in its first half and receives `delta_{l-1}` there; the second
/// half is scratch, so the step never reads what it has overwritten.
#[inline(always)]
pub(super) fn backward(w: &[f64], input: &[f64], n_out: usize, delta: &mut [f64]) {
    let n_in = input.len();
    let (cur, next) = delta.split_at_mut(MAX_WIDTH);
    let next = &mut next[..n_in];
    // Each input's sum runs over the units in order, as one dot product
    // per input would; the loop runs over the inputs, independent of one
    // another.
    next.fill(0.0);
    for (row, &d) in w.chunks_exact(n_in).zip(&cur[..n_out]) {
        for (acc, w) in next.iter_mut().zip(row) {
            *acc += w * d;
        }
    }
    for (acc, v) in next.iter_mut().zip(input) {
        *acc *= 1.0 - v * v;
    }
    cur[..n_in].copy_from_slice(next);
}

/// Add one sample's gradient to `grad`: `delta` holds its loss's
/// derivative by the output layer's values (in its first half, the second
/// scratch for [`backward`]), `acts` its forward pass's activations.
/// Layers from the last, each weight's term added once, in the order the
/// weights are stored.
#[inline(always)]
pub(super) fn add_sample_gradient(
    sizes: &[usize],
    offsets: &[usize],
    params: &[f64],
    acts: &[f64],
    delta: &mut [f64],
    grad: &mut [f64],
) {
    let layers = sizes.len() - 1;
    let mut s = params.len();
    for l in (0..layers).rev() {
        let (n_in, n_out) = (sizes[l], sizes[l + 1]);
        s -= n_out * (n_in + 1);
        let input = &acts[offsets[l]..offsets[l] + n_in];
        let (weights, biases) = grad[s..s + n_out * (n_in + 1)].split_at_mut(n_out * n_in);
        for ((row, bias), &d) in weights
            .chunks_exact_mut(n_in)
            .zip(biases)
            .zip(&delta[..n_out])
        {
            for (g, inp) in row.iter_mut().zip(input) {
                *g += d * inp;
            }
            *bias += d;
        }
        if l > 0 {
            backward(&params[s..s + n_out * n_in], input, n_out, delta);
        }
    }
}

/// `grad` (zeroed first) as the sum of `add`'s gradients of blocks of
/// [`BLOCK_SAMPLES`] `rows`, each given a block, its gradient to add to,
/// and scratch for `activations` values and a back-propagated delta: one
/// block on the calling thread, more in parallel, their gradients added
/// in block order, so the bits are the same on any thread count.
pub(super) fn gradient_by_blocks(
    rows: &[usize],
    grad: &mut [f64],
    activations: usize,
    add: impl Fn(&[usize], &mut [f64], &mut [f64], &mut [f64]) + Sync,
) {
    grad.fill(0.0);
    if rows.len() <= BLOCK_SAMPLES {
        add(
            rows,
            grad,
            &mut vec![0.0; activations],
            &mut vec![0.0; 2 * MAX_WIDTH],
        );
        return;
    }
    let partials: Vec<Vec<f64>> = rows
        .par_chunks(BLOCK_SAMPLES)
        .map_init(
            || (vec![0.0; activations], vec![0.0; 2 * MAX_WIDTH]),
            |(acts, delta), block| {
                let mut partial = vec![0.0; grad.len()];
                add(block, &mut partial, acts, delta);
                partial
            },
        )
        .collect();
    for partial in &partials {
        for (g, p) in grad.iter_mut().zip(partial) {
            *g += p;
        }
    }
}

/// Run `work` compiled for the widest vectors the processor offers (pulp
/// dispatches at run time). The training loops' arithmetic is elementwise,
/// a multiplication then an addition each rounded (Rust never fuses them),
/// so every width gives the same bits.
pub(super) fn widest_vectors<R>(work: impl FnOnce() -> R) -> R {
    pulp::Arch::new().dispatch(work)
}

/// The training problem of one restart: standardized data and buffers.
pub(super) struct Problem<'a> {
    pub(super) sizes: &'a [usize],
    pub(super) offsets: Vec<usize>,
    pub(super) x: &'a Array2<f64>,
    pub(super) t: &'a Array2<f64>,
    pub(super) train: &'a [usize],
    pub(super) held_out: &'a [usize],
    pub(super) decay: f64,
    /// Levenberg-Marquardt's Gauss-Newton matrix from the first this many
    /// training rows only (`None`: from all of them); its gradient, the
    /// cost and the steps' acceptance stay on every row.
    pub(super) curvature_rows: Option<usize>,
}

/// Samples per block of the training loops that run in parallel. The
/// blocks, and the order in which their partial sums are added, are fixed,
/// so every result is the same bits whatever the number of threads.
pub(super) const BLOCK_SAMPLES: usize = 256;

impl Problem<'_> {
    pub(super) fn n_params(&self) -> usize {
        parameter_count(self.sizes)
    }

    /// Scratch for one worker: every layer's activations.
    fn activations(&self) -> Vec<f64> {
        vec![0.0; self.offsets.last().copied().unwrap_or(0)]
    }

    /// Mean squared error over `rows`, per target value: blocks of rows in
    /// parallel, their sums added in block order.
    pub(super) fn mse(&self, params: &[f64], rows: &[usize]) -> f64 {
        let q = *self.sizes.last().unwrap_or(&1);
        let columns = by_columns(self.sizes, params);
        let columns = columns.as_slice();
        let sse: f64 = if rows.len() <= BLOCK_SAMPLES {
            self.sse(columns, rows, &mut self.activations())
        } else {
            rows.par_chunks(BLOCK_SAMPLES)
                .map_init(
                    || self.activations(),
                    |acts, block| self.sse(columns, block, acts),
                )
                .collect::<Vec<f64>>()
                .iter()
                .sum()
        };
        sse / (rows.len() * q).max(1) as f64
    }

    /// Sum of squared errors over `rows`, in row order, of the network
    /// whose weights are `columns` ([`by_columns`]).
    fn sse(&self, columns: &[f64], rows: &[usize], acts: &mut [f64]) -> f64 {
        widest_vectors(
            #[inline(always)]
            || self.sse_here(columns, rows, acts),
        )
    }

    #[inline(always)]
    fn sse_here(&self, columns: &[f64], rows: &[usize], acts: &mut [f64]) -> f64 {
        let q = *self.sizes.last().unwrap_or(&1);
        let out = self.offsets[self.sizes.len() - 1];
        let mut sse = 0.0;
        for &i in rows {
            let xi = self.x.row(i);
            let xi = xi.as_slice().unwrap_or(&[]);
            forward(self.sizes, columns, xi, acts, &self.offsets);
            for k in 0..q {
                sse += (acts[out + k] - self.t[[i, k]]).powi(2);
            }
        }
        sse
    }

    /// Every layer's activations a training sample takes (its input
    /// among them): what [`Self::residuals_keeping`] keeps a sample.
    pub(super) fn activations_per_sample(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    /// Residuals `output - target` of the training rows, row-major (rows x
    /// targets), into `r`, blocks of rows in parallel; each training
    /// sample's activations kept in `kept` where given
    /// ([`Self::activations_per_sample`] a sample, in training order), for
    /// [`Self::jacobian`] at the same weights.
    pub(super) fn residuals_keeping(
        &self,
        params: &[f64],
        r: &mut [f64],
        kept: Option<&mut [f64]>,
    ) {
        let q = *self.sizes.last().unwrap_or(&1);
        let out = self.offsets[self.sizes.len() - 1];
        let width = self.activations_per_sample();
        let columns = by_columns(self.sizes, params);
        let block =
            |acts: &mut Vec<f64>, r: &mut [f64], rows: &[usize], mut kept: Option<&mut [f64]>| {
                widest_vectors(
                    #[inline(always)]
                    || {
                        for (sample, (r, &i)) in r.chunks_exact_mut(q).zip(rows).enumerate() {
                            let xi = self.x.row(i);
                            forward(
                                self.sizes,
                                &columns,
                                xi.as_slice().unwrap_or(&[]),
                                acts,
                                &self.offsets,
                            );
                            for (k, r) in r.iter_mut().enumerate() {
                                *r = acts[out + k] - self.t[[i, k]];
                            }
                            if let Some(kept) = kept.as_deref_mut() {
                                kept[sample * width..(sample + 1) * width].copy_from_slice(acts);
                            }
                        }
                    },
                );
            };
        match kept {
            Some(kept) => r
                .par_chunks_mut(BLOCK_SAMPLES * q)
                .zip(kept.par_chunks_mut(BLOCK_SAMPLES * width))
                .zip(self.train.par_chunks(BLOCK_SAMPLES))
                .for_each_init(
                    || self.activations(),
                    |acts, ((r, kept), rows)| block(acts, r, rows, Some(kept)),
                ),
            None => r
                .par_chunks_mut(BLOCK_SAMPLES * q)
                .zip(self.train.par_chunks(BLOCK_SAMPLES))
                .for_each_init(
                    || self.activations(),
                    |acts, (r, rows)| block(acts, r, rows, None),
                ),
        }
    }

    pub(super) fn penalty(&self, params: &[f64]) -> f64 {
        self.decay * params.iter().map(|v| v * v).sum::<f64>()
    }

    /// Gradient of the mean squared error over `rows` (per target value)
    /// plus the weight decay term, by one backward pass per sample seeded
    /// with its residual: blocks of rows in parallel, their gradients added
    /// in block order (one block, as an Adam mini-batch usually is, runs
    /// on the calling thread).
    pub(super) fn gradient(&self, params: &[f64], rows: &[usize], grad: &mut [f64]) {
        let q = *self.sizes.last().unwrap_or(&1);
        let scale = 2.0 / (rows.len() * q).max(1) as f64;
        let columns = by_columns(self.sizes, params);
        let weights = (params, columns.as_slice());
        gradient_by_blocks(
            rows,
            grad,
            self.offsets.last().copied().unwrap_or(0),
            |block, grad, acts, delta| {
                self.add_gradient(weights, block, scale, grad, acts, delta);
            },
        );
        let decay = 2.0 * self.decay / (self.train.len() * q).max(1) as f64;
        for (g, p) in grad.iter_mut().zip(params) {
            *g += decay * p;
        }
    }

    /// Add `scale` times the gradient of the squared errors of `rows` to
    /// `grad`, in row order.
    fn add_gradient(
        &self,
        weights: (&[f64], &[f64]),
        rows: &[usize],
        scale: f64,
        grad: &mut [f64],
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        widest_vectors(
            #[inline(always)]
            || self.add_gradient_here(weights, rows, scale, grad, acts, delta),
        );
    }

    #[inline(always)]
    fn add_gradient_here(
        &self,
        (params, columns): (&[f64], &[f64]),
        rows: &[usize],
        scale: f64,
        grad: &mut [f64],
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        let sizes = self.sizes;
        let layers = sizes.len() - 1;
        let q = sizes[layers];
        let out = self.offsets[layers];
        for &i in rows {
            let xi = self.x.row(i);
            let xi = xi.as_slice().unwrap_or(&[]);
            forward(sizes, columns, xi, acts, &self.offsets);
            for k in 0..q {
                delta[k] = scale * (acts[out + k] - self.t[[i, k]]);
            }
            add_sample_gradient(sizes, &self.offsets, params, acts, delta, grad);
        }
    }

    /// The residuals r (training rows x targets, row-major) and the
    /// transposed Jacobian `J'` (parameters x residuals, column-major: each
    /// residual's derivatives are one contiguous column), blocks of rows in
    /// parallel.
    ///
    /// `kept`, where given, holds every training sample's activations at
    /// these weights ([`Self::residuals_keeping`]), which spares the
    /// forward passes.
    pub(super) fn jacobian(
        &self,
        params: &[f64],
        jt: &mut [f64],
        res: &mut [f64],
        kept: Option<&[f64]>,
    ) {
        let q = *self.sizes.last().unwrap_or(&1);
        let n = params.len();
        let width = self.activations_per_sample();
        let columns = by_columns(self.sizes, params);
        let weights = (params, columns.as_slice());
        jt.par_chunks_mut(n * BLOCK_SAMPLES * q)
            .zip(res.par_chunks_mut(BLOCK_SAMPLES * q))
            .zip(self.train.par_chunks(BLOCK_SAMPLES))
            .enumerate()
            .for_each_init(
                || (self.activations(), vec![0.0; 2 * MAX_WIDTH]),
                |(acts, delta), (block, ((jt, res), rows))| {
                    let kept = kept.map(|k| {
                        let first = block * BLOCK_SAMPLES * width;
                        &k[first..first + rows.len() * width]
                    });
                    self.jacobian_block(weights, rows, (jt, res), kept, acts, delta);
                },
            );
    }

    /// What a network of one hidden layer's Gauss-Newton products are made
    /// of, per training sample `n`: the columns
    /// `ut[.., n] = s_n (x) [x_n; 1]` (hidden unit by hidden unit, `s` the
    /// slopes `1 - z^2` of the tanh units), `zt[.., n] = [z_n; 1]` and the
    /// residuals `output - target` (samples x targets, row-major); blocks
    /// of samples in parallel.
    pub(super) fn hidden_layer_terms(
        &self,
        params: &[f64],
        ut: &mut [f64],
        zt: &mut [f64],
        res: &mut [f64],
    ) {
        let (d, h, q) = (self.sizes[0], self.sizes[1], self.sizes[2]);
        let columns = by_columns(self.sizes, params);
        let (unit_rows, hidden_rows) = (h * (d + 1), h + 1);
        ut.par_chunks_mut(unit_rows * BLOCK_SAMPLES)
            .zip(zt.par_chunks_mut(hidden_rows * BLOCK_SAMPLES))
            .zip(res.par_chunks_mut(q * BLOCK_SAMPLES))
            .zip(self.train.par_chunks(BLOCK_SAMPLES))
            .for_each_init(
                || self.activations(),
                |acts, (((ut, zt), res), rows)| {
                    widest_vectors(
                        #[inline(always)]
                        || {
                            for (((u, z), r), &i) in ut
                                .chunks_exact_mut(unit_rows)
                                .zip(zt.chunks_exact_mut(hidden_rows))
                                .zip(res.chunks_exact_mut(q))
                                .zip(rows)
                            {
                                let xi = self.x.row(i);
                                let xi = xi.as_slice().unwrap_or(&[]);
                                forward(self.sizes, &columns, xi, acts, &self.offsets);
                                let hidden = &acts[d..d + h];
                                for (unit, &a) in u.chunks_exact_mut(d + 1).zip(hidden) {
                                    let slope = 1.0 - a * a;
                                    let (weights, bias) = unit.split_at_mut(d);
                                    for (slot, &x) in weights.iter_mut().zip(xi) {
                                        *slot = slope * x;
                                    }
                                    bias[0] = slope;
                                }
                                z[..h].copy_from_slice(hidden);
                                z[h] = 1.0;
                                for (k, r) in r.iter_mut().enumerate() {
                                    *r = acts[d + h + k] - self.t[[i, k]];
                                }
                            }
                        },
                    )
                },
            );
    }

    /// [`Self::jacobian`] for the samples `rows`, on one thread.
    fn jacobian_block(
        &self,
        weights: (&[f64], &[f64]),
        rows: &[usize],
        out: (&mut [f64], &mut [f64]),
        kept: Option<&[f64]>,
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        widest_vectors(
            #[inline(always)]
            || self.jacobian_block_here(weights, rows, out, kept, acts, delta),
        );
    }

    #[inline(always)]
    fn jacobian_block_here(
        &self,
        (params, columns): (&[f64], &[f64]),
        rows: &[usize],
        (jt, res): (&mut [f64], &mut [f64]),
        kept: Option<&[f64]>,
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        let width = self.activations_per_sample();
        let sizes = self.sizes;
        let layers = sizes.len() - 1;
        let q = sizes[layers];
        let out = self.offsets[layers];
        // Start of each layer's parameters.
        let mut starts = Vec::with_capacity(layers);
        let mut p = 0;
        for l in 0..layers {
            starts.push(p);
            p += sizes[l + 1] * (sizes[l] + 1);
        }
        for (sample, &i) in rows.iter().enumerate() {
            match kept {
                Some(kept) => acts.copy_from_slice(&kept[sample * width..(sample + 1) * width]),
                None => {
                    let xi = self.x.row(i);
                    forward(
                        sizes,
                        columns,
                        xi.as_slice().unwrap_or(&[]),
                        acts,
                        &self.offsets,
                    );
                }
            }
            for k in 0..q {
                let r = sample * q + k;
                res[r] = acts[out + k] - self.t[[i, k]];
                let column = &mut jt[r * params.len()..(r + 1) * params.len()];
                // Back-propagate the unit seed of output k.
                delta[..q].fill(0.0);
                delta[k] = 1.0;
                for l in (0..layers).rev() {
                    let (n_in, n_out) = (sizes[l], sizes[l + 1]);
                    let input = &acts[self.offsets[l]..self.offsets[l] + n_in];
                    let s = starts[l];
                    for a in 0..n_out {
                        let d = delta[a];
                        for (slot, inp) in column[s + a * n_in..s + (a + 1) * n_in]
                            .iter_mut()
                            .zip(input)
                        {
                            *slot = d * inp;
                        }
                        column[s + n_out * n_in + a] = d;
                    }
                    if l > 0 {
                        backward(&params[s..s + n_out * n_in], input, n_out, delta);
                    }
                }
            }
        }
    }
}

/// Glorot-uniform weights, small random biases.
pub(super) fn initial_parameters(sizes: &[usize], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut params = Vec::with_capacity(parameter_count(sizes));
    for w in sizes.windows(2) {
        let (n_in, n_out) = (w[0], w[1]);
        let limit = (6.0 / (n_in + n_out) as f64).sqrt();
        params.extend((0..n_out * n_in).map(|_| rng.random_range(-limit..limit)));
        params.extend((0..n_out).map(|_| rng.random_range(-0.5..0.5)));
    }
    params
}

impl Predictor for FittedMlp {
    fn n_inputs(&self) -> usize {
        self.sizes[0]
    }

    fn n_outputs(&self) -> usize {
        *self.sizes.last().unwrap_or(&0)
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()> {
        let q = self.n_outputs();
        check::row_lengths(x, out, self.n_inputs(), q)?;
        let mut input = [0.0f64; MAX_WIDTH];
        self.features.transform_into(x, &mut input[..self.sizes[0]]);
        out.fill(0.0);
        let mut output = [0.0f64; MAX_WIDTH];
        for params in &self.members {
            run_network(&self.sizes, params, &input, &mut output);
            for (o, v) in out.iter_mut().zip(&output[..q]) {
                *o += v;
            }
        }
        let members = self.members.len() as f64;
        for o in out.iter_mut() {
            *o /= members;
        }
        self.targets.inverse_in_place(out);
        Ok(())
    }
}

/// Number of weights and biases of a network with layer sizes `[n_in,
/// hidden.., n_out]`: what a Levenberg-Marquardt step's cost grows with.
///
/// ```
/// assert_eq!(twostage_fit::n_parameters(&[10, 20, 2]), 20 * 11 + 2 * 21);
/// ```
pub fn n_parameters(sizes: &[usize]) -> usize {
    parameter_count(sizes)
}

#[cfg(test)]
mod tests;
