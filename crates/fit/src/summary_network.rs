//! The training of a stage 1 that learns: the summary network
//! of `twostage_compress` (strided tanh convolutions over a record's
//! samples, pooled by time averages) is trained end to end with a
//! one-hidden-layer head on the chart's parameters (Adam on the
//! standardized squared error, held-out stopping); the head is then set
//! aside and stage 2 is fitted on the summary, beside whatever other
//! features the run compresses, so that intervals, certificates and flags
//! stay stage 2's.
//!
//! Deterministic: a mini-batch's gradient is summed over fixed chunks of
//! records, each in order, and the chunks' sums in order, so the bits do
//! not depend on the thread count.

use ndarray::{Array2, ArrayView2};
use rand::RngExt;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use twostage_compress::{ConvShape, LearnedShape, SummaryNetwork};
use twostage_kernels::convolution::{convolve_tanh, min_samples, pool_mean_and_square};
use twostage_kernels::tanh;

use crate::TerminationReason;
use crate::adam::Adam;
use crate::error::{FitError, InvalidSetting, Result};
use crate::mlp::BestHeldOut;
use crate::standardize::Standardizer;

/// Records whose gradients one task sums: fixed, so that the order of
/// every sum is the same at any thread count.
const GRADIENT_CHUNK: usize = 8;

/// How the summary network is shaped and trained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SummaryTraining {
    /// The convolutions' channels (the summary has twice as many numbers
    /// as the last), kernel and stride.
    pub shape: LearnedShape,
    /// Hidden units of the head trained with it.
    pub head: usize,
    /// Adam's step.
    pub learning_rate: f64,
    /// Records per mini-batch.
    pub batch_size: usize,
    /// Most passes over the training records.
    pub epochs: usize,
    /// Passes without a better held-out loss before stopping.
    pub patience: usize,
    /// Share of the records held out for stopping.
    pub held_out: f64,
    /// Seeds the initial weights, the held-out split and the batches.
    pub seed: u64,
    /// When the training's time is up: no epoch starts after it, and the
    /// best held-out weights so far are the answer (a search's budget;
    /// `None` trains until `epochs` or `patience` stop it, the same bits on
    /// any machine).
    #[serde(skip)]
    pub stop_by: Option<std::time::Instant>,
}

impl Default for SummaryTraining {
    fn default() -> Self {
        Self {
            shape: LearnedShape::default(),
            head: 16,
            learning_rate: 3e-3,
            batch_size: 32,
            epochs: 80,
            patience: 15,
            held_out: 0.1,
            seed: 0,
            stop_by: None,
        }
    }
}

/// What the training of a summary network reports.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainedSummary {
    /// The network (its head set aside).
    pub network: SummaryNetwork,
    /// Passes over the training records.
    pub epochs: usize,
    /// Why it stopped.
    pub reason: TerminationReason,
    /// Held-out mean squared error of the standardized parameters through
    /// the head, at the kept weights.
    pub held_out_mse: f64,
    /// The held-out mean squared error before training and after each epoch.
    pub history: Vec<f64>,
}

/// The whole trained map's shape: convolutions, then head, in one flat
/// vector of weights.
#[derive(Debug, Clone)]
struct Layout {
    layers: Vec<ConvShape>,
    head: usize,
    targets: usize,
}

impl Layout {
    fn conv_weights(&self) -> usize {
        self.layers.iter().map(ConvShape::n_weights).sum()
    }
    fn features(&self) -> usize {
        2 * channels_of(&self.layers)
    }
    fn n_weights(&self) -> usize {
        self.conv_weights() + self.head * (self.features() + 1) + self.targets * (self.head + 1)
    }
}

/// Activations of every layer of one record, kept for the backward pass.
struct Pass {
    /// `acts[0]` is the scaled record (channel-major); `acts[l + 1]` layer l's tanh.
    acts: Vec<Vec<f64>>,
    lengths: Vec<usize>,
}

fn forward_convolutions(
    layers: &[ConvShape],
    weights: &[f64],
    record: Vec<f64>,
    length: usize,
) -> Pass {
    let mut acts = vec![record];
    let mut lengths = vec![length];
    let mut offset = 0;
    for shape in layers {
        let input = &acts[acts.len() - 1];
        let length_in = lengths[lengths.len() - 1];
        let mut out = vec![0.0; shape.outputs * shape.positions(length_in)];
        let length_out = convolve_tanh(
            *shape,
            &weights[offset..offset + shape.n_weights()],
            input,
            length_in,
            &mut out,
        );
        offset += shape.n_weights();
        acts.push(out);
        lengths.push(length_out);
    }
    Pass { acts, lengths }
}

/// Channels of the last layer, each pooled twice.
fn channels_of(layers: &[ConvShape]) -> usize {
    layers.last().map_or(0, |l| l.outputs)
}

/// The time averages of the last layer's channels and of their squares:
/// the squares keep what a family steered as much left as right averages
/// away in odd functions of the record (a gain is in `u y`, not `u`).
fn pooled(pass: &Pass, channels: usize) -> Vec<f64> {
    let mut out = vec![0.0; 2 * channels];
    pool_mean_and_square(
        &pass.acts[pass.acts.len() - 1],
        channels,
        pass.lengths[pass.lengths.len() - 1],
        &mut out,
    );
    out
}

/// `record` (samples x signals) divided by `scales`, channel-major.
fn scaled(record: ArrayView2<'_, f64>, scales: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(record.len());
    for (column, scale) in record.columns().into_iter().zip(scales) {
        out.extend(column.iter().map(|v| v / scale));
    }
    out
}

/// The squared error of one record through the convolutions and the head
/// (standardized targets `y`), and its gradient added to `gradient`.
fn loss_and_gradient(
    layout: &Layout,
    weights: &[f64],
    record: Vec<f64>,
    length: usize,
    y: &[f64],
    gradient: Option<&mut [f64]>,
) -> f64 {
    let pass = forward_convolutions(&layout.layers, weights, record, length);
    let f = pooled(&pass, channels_of(&layout.layers));
    let conv = layout.conv_weights();
    let (nf, nh, ny) = (f.len(), layout.head, layout.targets);
    let (w1, rest) = weights[conv..].split_at(nh * nf);
    let (b1, rest) = rest.split_at(nh);
    let (w2, b2) = rest.split_at(ny * nh);
    let h: Vec<f64> = (0..nh)
        .map(|j| {
            tanh(
                b1[j]
                    + w1[j * nf..(j + 1) * nf]
                        .iter()
                        .zip(&f)
                        .map(|(a, x)| a * x)
                        .sum::<f64>(),
            )
        })
        .collect();
    let residual: Vec<f64> = (0..ny)
        .map(|k| {
            b2[k]
                + w2[k * nh..(k + 1) * nh]
                    .iter()
                    .zip(&h)
                    .map(|(a, x)| a * x)
                    .sum::<f64>()
                - y[k]
        })
        .collect();
    let loss = residual.iter().map(|r| r * r).sum::<f64>() / ny as f64;
    let Some(gradient) = gradient else {
        return loss;
    };
    // d loss / d output = 2 r / ny.
    let d_out: Vec<f64> = residual.iter().map(|r| 2.0 * r / ny as f64).collect();
    let (g_conv, g_head) = gradient.split_at_mut(conv);
    let (g_w1, rest) = g_head.split_at_mut(nh * nf);
    let (g_b1, rest) = rest.split_at_mut(nh);
    let (g_w2, g_b2) = rest.split_at_mut(ny * nh);
    let mut d_h = vec![0.0; nh];
    for k in 0..ny {
        g_b2[k] += d_out[k];
        for j in 0..nh {
            g_w2[k * nh + j] += d_out[k] * h[j];
            d_h[j] += d_out[k] * w2[k * nh + j];
        }
    }
    let mut d_f = vec![0.0; nf];
    for j in 0..nh {
        let d_z = d_h[j] * (1.0 - h[j] * h[j]);
        g_b1[j] += d_z;
        for i in 0..nf {
            g_w1[j * nf + i] += d_z * f[i];
            d_f[i] += d_z * w1[j * nf + i];
        }
    }
    // Through the averages: position t of channel c gets (d_mean[c] +
    // 2 a d_square[c]) / length.
    let last = layout.layers.len();
    let length_last = pass.lengths[last];
    let channels = nf / 2;
    let top = &pass.acts[last];
    let mut d_act: Vec<f64> = (0..channels * length_last)
        .map(|i| {
            let c = i / length_last;
            (d_f[c] + 2.0 * top[i] * d_f[channels + c]) / length_last as f64
        })
        .collect();
    let mut offset = conv;
    for l in (0..last).rev() {
        let shape = layout.layers[l];
        offset -= shape.n_weights();
        let n_w = shape.outputs * shape.inputs * shape.kernel;
        let (w, _) = weights[offset..offset + shape.n_weights()].split_at(n_w);
        let (g_w, g_b) = g_conv[offset..offset + shape.n_weights()].split_at_mut(n_w);
        let (input, output) = (&pass.acts[l], &pass.acts[l + 1]);
        let (length_in, length_out) = (pass.lengths[l], pass.lengths[l + 1]);
        let mut d_in = vec![0.0; if l > 0 { shape.inputs * length_in } else { 0 }];
        for o in 0..shape.outputs {
            for t in 0..length_out {
                let a = output[o * length_out + t];
                let d_z = d_act[o * length_out + t] * (1.0 - a * a);
                g_b[o] += d_z;
                for c in 0..shape.inputs {
                    let base = (o * shape.inputs + c) * shape.kernel;
                    let start = c * length_in + t * shape.stride;
                    for k in 0..shape.kernel {
                        g_w[base + k] += d_z * input[start + k];
                        if l > 0 {
                            d_in[start + k] += d_z * w[base + k];
                        }
                    }
                }
            }
        }
        d_act = d_in;
    }
    loss
}

impl SummaryTraining {
    fn check(&self, n_records: usize, signals: usize, length: usize) -> Result<Layout> {
        let bad = |name: &'static str, value: String, reason: &str| {
            Err(FitError::InvalidSetting(InvalidSetting {
                name,
                value,
                reason: reason.into(),
            }))
        };
        self.shape.check().map_err(|e| match e {
            twostage_compress::CompressError::InvalidSetting(setting) => {
                FitError::InvalidSetting(setting)
            }
            other => FitError::ShapeMismatch(other.to_string()),
        })?;
        if self.head == 0
            || !(self.learning_rate.is_finite() && self.learning_rate > 0.0)
            || self.batch_size == 0
            || self.epochs == 0
        {
            return bad(
                "summary training",
                format!(
                    "head {}, learning rate {}, batch {}, epochs {}",
                    self.head, self.learning_rate, self.batch_size, self.epochs
                ),
                "a head of 1 unit or more, a positive learning rate, batches and epochs of 1 or more",
            );
        }
        if !(self.held_out > 0.0 && self.held_out < 0.5) {
            return bad(
                "summary held_out",
                self.held_out.to_string(),
                "a share between 0 and 0.5",
            );
        }
        let layers = self.shape.layers(signals);
        let shortest = min_samples(&layers);
        if length < shortest {
            return Err(FitError::ShapeMismatch(format!(
                "records of {length} samples: {} convolutions of kernel {} and stride {} need {shortest} or more",
                layers.len(),
                self.shape.kernel,
                self.shape.stride
            )));
        }
        let held = (n_records as f64 * self.held_out).round() as usize;
        if held == 0 || n_records - held < 2 {
            return Err(FitError::TooFewSamples {
                got: n_records,
                needed: (2.0 / (1.0 - self.held_out))
                    .ceil()
                    .max(1.0 / self.held_out) as usize
                    + 1,
                why: "some records held out for stopping and two or more to train on".into(),
            });
        }
        Ok(Layout {
            layers,
            head: self.head,
            targets: 0,
        })
    }

    /// Train on `records` (each samples x signals, inputs then outputs, all
    /// of one length) and their parameters `targets` (a row per record).
    ///
    /// ```
    /// use ndarray::Array2;
    /// use twostage_compress::{LearnedShape, Workspace};
    /// use twostage_fit::SummaryTraining;
    ///
    /// // y = g u on a random input: the gain g in every record's samples.
    /// let gains: Vec<f64> = (0..200).map(|i| 0.5 + (i % 10) as f64 / 5.0).collect();
    /// let records: Vec<Array2<f64>> = gains
    ///     .iter()
    ///     .enumerate()
    ///     .map(|(i, g)| {
    ///         Array2::from_shape_fn((32, 2), |(k, s)| {
    ///             let u = (((i * 31 + k * 17) % 13) as f64 - 6.0) / 6.0;
    ///             if s == 0 { u } else { g * u }
    ///         })
    ///     })
    ///     .collect();
    /// let targets = Array2::from_shape_vec((200, 1), gains)?;
    /// let shape = LearnedShape { channels: vec![4, 4], ..Default::default() };
    /// let training = SummaryTraining { shape, epochs: 3, ..Default::default() };
    /// let trained = training.train(&records, targets.view())?;
    /// // Two numbers per last channel: its mean and its mean square.
    /// assert_eq!(trained.network.n_features(), 8);
    /// assert_eq!(trained.history.len(), trained.epochs + 1);
    /// let mut summary = [0.0; 8];
    /// let (u, y) = (records[0].slice(ndarray::s![.., ..1]), records[0].slice(ndarray::s![.., 1..]));
    /// trained.network.summarize(u, y, &mut Workspace::new(), &mut summary)?;
    /// assert!(summary[4..].iter().all(|v| (0.0..1.0).contains(v)));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// Mismatched shapes, non-finite values, a signal that is zero in
    /// every record, too few records, or an impossible setting.
    pub fn train(
        &self,
        records: &[Array2<f64>],
        targets: ArrayView2<'_, f64>,
    ) -> Result<TrainedSummary> {
        let Some(first) = records.first() else {
            return Err(FitError::TooFewSamples {
                got: 0,
                needed: 3,
                why: "a summary network learns from records".into(),
            });
        };
        let (length, signals) = first.dim();
        if targets.nrows() != records.len() {
            return Err(FitError::ShapeMismatch(format!(
                "{} records and {} target rows",
                records.len(),
                targets.nrows()
            )));
        }
        if let Some(i) = records.iter().position(|r| r.dim() != (length, signals)) {
            return Err(FitError::ShapeMismatch(format!(
                "record {i} is {:?} (samples, signals); record 0 is {:?}",
                records[i].dim(),
                (length, signals)
            )));
        }
        for (row, record) in records.iter().enumerate() {
            if let Some(((_, col), value)) = record.indexed_iter().find(|(_, v)| !v.is_finite()) {
                return Err(FitError::NonFinite {
                    what: "records",
                    row,
                    col,
                    value: *value,
                });
            }
        }
        let mut layout = self.check(records.len(), signals, length)?;
        layout.targets = targets.ncols();
        let standard = Standardizer::fit(targets);
        let y = standard.transform(targets);
        let scales: Vec<f64> = (0..signals)
            .map(|s| {
                let power: f64 = records
                    .iter()
                    .map(|r| r.column(s).iter().map(|v| v * v).sum::<f64>())
                    .sum();
                (power / (records.len() * length) as f64).sqrt()
            })
            .collect();
        if let Some(s) = scales.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "summary network signals",
                value: format!("signal {s} zero in every record"),
                reason: "a signal that never moves tells nothing: leave it out".into(),
            }));
        }

        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5355_4d4d);
        let mut weights = Vec::with_capacity(layout.n_weights());
        let mut init = |fan_in: usize, n: usize, biases: usize, w: &mut Vec<f64>| {
            let bound = (3.0 / fan_in as f64).sqrt();
            w.extend((0..n).map(|_| rng.random_range(-bound..bound)));
            w.extend(std::iter::repeat_n(0.0, biases));
        };
        for l in &layout.layers {
            init(
                l.inputs * l.kernel,
                l.outputs * l.inputs * l.kernel,
                l.outputs,
                &mut weights,
            );
        }
        init(
            layout.features(),
            layout.head * layout.features(),
            layout.head,
            &mut weights,
        );
        init(
            layout.head,
            layout.targets * layout.head,
            layout.targets,
            &mut weights,
        );

        let mut order: Vec<usize> = (0..records.len()).collect();
        order.shuffle(&mut rng);
        let held = (records.len() as f64 * self.held_out).round() as usize;
        let (held_out, train) = order.split_at(held);
        let (held_out, mut train) = (held_out.to_vec(), train.to_vec());

        let input = |i: usize| scaled(records[i].view(), &scales);
        let batch_loss = |w: &[f64], rows: &[usize], gradient: Option<&mut [f64]>| -> f64 {
            let n = layout.n_weights();
            let parts: Vec<(f64, Vec<f64>)> = rows
                .par_chunks(GRADIENT_CHUNK)
                .map(|chunk| {
                    let mut g = vec![0.0; if gradient.is_some() { n } else { 0 }];
                    let mut loss = 0.0;
                    for &i in chunk {
                        let target = y.row(i);
                        let target = target.as_slice().unwrap_or(&[]);
                        loss += loss_and_gradient(
                            &layout,
                            w,
                            input(i),
                            length,
                            target,
                            if gradient.is_some() {
                                Some(&mut g)
                            } else {
                                None
                            },
                        );
                    }
                    (loss, g)
                })
                .collect();
            let mut total = 0.0;
            let scale = 1.0 / rows.len() as f64;
            if let Some(gradient) = gradient {
                gradient.fill(0.0);
                for (loss, g) in &parts {
                    total += loss;
                    gradient
                        .iter_mut()
                        .zip(g)
                        .for_each(|(a, b)| *a += b * scale);
                }
            } else {
                total = parts.iter().map(|(l, _)| l).sum();
            }
            total * scale
        };

        let mut adam = Adam::new(layout.n_weights(), self.learning_rate);
        let mut gradient = vec![0.0; layout.n_weights()];
        let mut history = vec![batch_loss(&weights, &held_out, None)];
        let mut best = BestHeldOut::new(history[0], &weights, self.patience, true);
        let (mut epochs, mut reason) = (0, TerminationReason::MaxEpochs);
        for _ in 0..self.epochs {
            if self.stop_by.is_some_and(|t| std::time::Instant::now() >= t) {
                reason = TerminationReason::EpochsUntilDeadline;
                break;
            }
            epochs += 1;
            train.shuffle(&mut rng);
            for batch in train.chunks(self.batch_size) {
                batch_loss(&weights, batch, Some(&mut gradient));
                adam.step(&mut weights, &gradient);
            }
            let loss = batch_loss(&weights, &held_out, None);
            history.push(loss);
            if best.observe(loss, &weights) {
                reason = TerminationReason::EpochsWithoutImprovement;
                break;
            }
        }
        let (held_out_mse, mut weights) = best.into_best();
        weights.truncate(layout.conv_weights());
        Ok(TrainedSummary {
            network: SummaryNetwork::new(scales, layout.layers, weights)
                .map_err(|e| FitError::ShapeMismatch(e.to_string()))?,
            epochs,
            reason,
            held_out_mse,
            history,
        })
    }
}

#[cfg(test)]
mod tests;
