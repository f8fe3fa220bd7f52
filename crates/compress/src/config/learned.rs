//! A stage 1 that learns: a small
//! one-dimensional convolutional network over a record's samples, every
//! signal a channel, whose last layer's activations and their squares are
//! averaged over time into a few summary numbers, beside (or instead of)
//! another compressor's features (`SPEC+learned`, `learned`).
//!
//! Strided convolutions with tanh see a record a few samples at a time,
//! as an ARX fit does, but through nonlinear filters of their own; the
//! averages over time make the summary independent of the record's
//! length, as least-squares coefficients are. The network is trained with
//! the estimator (`twostage_fit::SummaryTraining`, on the training
//! records and their parameters); until then the compressor is
//! *untrained* and refuses to compress.

use crate::InvalidSetting;
use std::fmt;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
pub use twostage_kernels::convolution::ConvShape;
use twostage_kernels::convolution::{convolve_tanh, min_samples, pool_mean_and_square};

use super::CompressorConfig;
use crate::error::{CompressError, Result};
use crate::{Compressor, Workspace};

/// The architecture a `learned` specification asks for before training.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LearnedShape {
    /// Channels of each convolution, first to last.
    pub channels: Vec<usize>,
    /// Kernel width of every convolution.
    pub kernel: usize,
    /// Stride of every convolution.
    pub stride: usize,
}

impl Default for LearnedShape {
    fn default() -> Self {
        Self {
            channels: vec![8, 8, 8],
            kernel: 5,
            stride: 2,
        }
    }
}

impl LearnedShape {
    /// Layers of this shape over `signals` signals.
    pub fn layers(&self, signals: usize) -> Vec<ConvShape> {
        let mut inputs = signals;
        self.channels
            .iter()
            .map(|&outputs| {
                let shape = ConvShape {
                    inputs,
                    outputs,
                    kernel: self.kernel,
                    stride: self.stride,
                };
                inputs = outputs;
                shape
            })
            .collect()
    }

    /// Refuses channels, kernels and strides the network cannot have.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] naming the setting.
    pub fn check(&self) -> Result<()> {
        let refuse = |value: String, reason: &str| {
            Err(CompressError::InvalidSetting(InvalidSetting {
                name: "learned",
                value,
                reason: reason.into(),
            }))
        };
        if self.channels.is_empty()
            || self.channels.len() > 6
            || self.channels.iter().any(|&c| c == 0 || c > 64)
        {
            return refuse(
                format!("channels {:?}", self.channels),
                "one to six layers of 1 to 64 channels (e.g. learned:8,8,8)",
            );
        }
        if self.kernel == 0 || self.stride == 0 || self.stride > self.kernel {
            return refuse(
                format!("kernel {} and stride {}", self.kernel, self.stride),
                "a kernel of 1 sample or more and a stride from 1 to the kernel, so that no \
                 sample is skipped",
            );
        }
        Ok(())
    }

    /// The specification's part after `learned:`.
    fn spec(&self) -> String {
        let channels: Vec<String> = self.channels.iter().map(ToString::to_string).collect();
        channels.join(",")
    }
}

/// A trained summary network: each signal's scale, the convolutions and
/// their weights. [`SummaryNetwork::summarize`] maps a record to
/// [`SummaryNetwork::n_features`] numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "SummaryNetworkFields")]
pub struct SummaryNetwork {
    /// Each signal is divided by its scale (its RMS over the training
    /// records), inputs first.
    scales: Vec<f64>,
    layers: Vec<ConvShape>,
    /// Layer after layer: taps (out x in x kernel, row-major), then biases.
    weights: Vec<f64>,
}

/// A network as a file stores it, checked by [`SummaryNetwork::new`]
/// before it is believed (a damaged file must not index past a layer).
#[derive(Deserialize)]
struct SummaryNetworkFields {
    scales: Vec<f64>,
    layers: Vec<ConvShape>,
    weights: Vec<f64>,
}

impl TryFrom<SummaryNetworkFields> for SummaryNetwork {
    type Error = CompressError;
    fn try_from(f: SummaryNetworkFields) -> Result<Self> {
        Self::new(f.scales, f.layers, f.weights)
    }
}

impl SummaryNetwork {
    /// A network of `layers` with `weights` over signals divided by
    /// `scales`.
    ///
    /// ```
    /// use twostage_compress::{ConvShape, SummaryNetwork};
    /// let layer = ConvShape { inputs: 2, outputs: 1, kernel: 2, stride: 1 };
    /// let net = SummaryNetwork::new(vec![1.0, 1.0], vec![layer], vec![0.0; 5])?;
    /// assert_eq!((net.n_features(), net.min_samples()), (2, 2));
    /// assert!(SummaryNetwork::new(vec![1.0], vec![layer], vec![0.0; 5]).is_err());
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for layers that do not chain
    /// (the first's inputs the signals, each next's inputs the last's
    /// outputs), a weight count that does not match, or a scale that is
    /// not positive and finite.
    pub fn new(scales: Vec<f64>, layers: Vec<ConvShape>, weights: Vec<f64>) -> Result<Self> {
        let refuse = |value: String, reason: &str| {
            Err(CompressError::InvalidSetting(InvalidSetting {
                name: "summary network",
                value,
                reason: reason.into(),
            }))
        };
        let mut inputs = scales.len();
        for (l, layer) in layers.iter().enumerate() {
            if layer.inputs != inputs
                || layer.outputs == 0
                || layer.kernel == 0
                || layer.stride == 0
                || layer.outputs > 64
                || layer.kernel > 4096
            {
                return refuse(
                    format!("layer {l}: {layer:?}"),
                    "each layer's inputs are the signals (the first's) or the last layer's \
                     channels, with 1 to 64 channels, a kernel and a stride of 1 or more",
                );
            }
            inputs = layer.outputs;
        }
        if layers.is_empty() {
            return refuse("no layers".into(), "one convolution or more");
        }
        let wanted: usize = layers.iter().map(ConvShape::n_weights).sum();
        if weights.len() != wanted {
            return refuse(
                format!("{} weights", weights.len()),
                &format!("{wanted} for these layers"),
            );
        }
        if let Some(s) = scales.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
            return refuse(
                format!("scale {s} = {}", scales[s]),
                "a positive, finite scale per signal",
            );
        }
        Ok(Self {
            scales,
            layers,
            weights,
        })
    }

    /// Summary numbers per record: two per channel of the last layer
    /// (its time average, then the average of its square).
    pub fn n_features(&self) -> usize {
        2 * self.channels()
    }

    fn channels(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }

    /// Signals a record must have, inputs then outputs.
    pub fn n_signals(&self) -> usize {
        self.scales.len()
    }

    /// The shortest record with at least one position in the last layer.
    pub fn min_samples(&self) -> usize {
        min_samples(&self.layers)
    }

    /// The convolutions, first to last.
    pub fn layers(&self) -> &[ConvShape] {
        &self.layers
    }

    /// The weights, layer after layer.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Each signal's scale, inputs first.
    pub fn scales(&self) -> &[f64] {
        &self.scales
    }

    /// The summary of the record of `inputs` and `outputs` (a column per
    /// signal) into `out`, through `work`'s buffers.
    ///
    /// # Errors
    /// [`CompressError::ShapeMismatch`] for another number of signals,
    /// [`CompressError::RecordTooShort`] for a record shorter than
    /// [`Self::min_samples`], [`CompressError::NonFinite`] for a sample
    /// that is not finite, [`CompressError::InvalidSetting`] for a buffer
    /// of another length than [`Self::n_features`].
    pub fn summarize(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        out: &mut [f64],
    ) -> Result<()> {
        let signals = inputs.ncols() + outputs.ncols();
        if signals != self.n_signals() {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "record",
                value: format!(
                    "{} input(s) and {} output(s)",
                    inputs.ncols(),
                    outputs.ncols()
                ),
                reason: format!("the summary network reads {} signals", self.n_signals()),
            }));
        }
        if out.len() != self.n_features() {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "feature buffer",
                value: out.len().to_string(),
                reason: format!("{} summary numbers", self.n_features()),
            }));
        }
        let length = outputs.nrows();
        if inputs.ncols() > 0 && inputs.nrows() != length {
            return Err(CompressError::LengthMismatch {
                inputs: inputs.nrows(),
                outputs: length,
            });
        }
        if length < self.min_samples() {
            return Err(CompressError::RecordTooShort {
                n_samples: length,
                needed: self.min_samples(),
                structure: format!("the summary network ({})", self.describe()),
            });
        }
        let [current, next] = &mut work.learned;
        current.clear();
        let columns = inputs.columns().into_iter().chain(outputs.columns());
        for (j, (column, scale)) in columns.zip(&self.scales).enumerate() {
            for (index, v) in column.iter().enumerate() {
                if !v.is_finite() {
                    return Err(CompressError::NonFinite {
                        signal: crate::signals::name(
                            if j < inputs.ncols() { "u" } else { "y" },
                            if j < inputs.ncols() {
                                j
                            } else {
                                j - inputs.ncols()
                            },
                            if j < inputs.ncols() {
                                inputs.ncols()
                            } else {
                                outputs.ncols()
                            },
                        ),
                        index,
                        value: *v,
                    });
                }
                current.push(v / scale);
            }
        }
        let mut length_in = length;
        let mut offset = 0;
        for shape in &self.layers {
            let length_out = shape.positions(length_in);
            next.clear();
            next.resize(shape.outputs * length_out, 0.0);
            convolve_tanh(
                *shape,
                &self.weights[offset..offset + shape.n_weights()],
                current,
                length_in,
                next,
            );
            offset += shape.n_weights();
            std::mem::swap(current, next);
            length_in = length_out;
        }
        pool_mean_and_square(current, self.channels(), length_in, out);
        Ok(())
    }

    /// `8,8,8 channels, kernel 5, stride 2`.
    fn describe(&self) -> String {
        let channels: Vec<String> = self.layers.iter().map(|l| l.outputs.to_string()).collect();
        let first = self.layers.first();
        format!(
            "{} channels, kernel {}, stride {}",
            channels.join(","),
            first.map_or(0, |l| l.kernel),
            first.map_or(0, |l| l.stride)
        )
    }
}

/// Another compressor's features (when there is one), then a summary
/// network's: `SPEC+learned:C1,C2,..` or `learned:C1,C2,..` alone
/// (`learned` and `+learned` take 8,8,8 channels, kernel 5, stride 2).
///
/// ```
/// use twostage_compress::{Compressor, CompressorConfig};
/// let c: CompressorConfig = "arx:2,2+summary+learned".parse()?;
/// assert_eq!(c.spec().as_deref(), Some("arx:2,2+summary+learned:8,8,8"));
/// let alone: CompressorConfig = "learned:4,4".parse()?;
/// // Untrained: it knows its features' count but compresses nothing yet.
/// assert_eq!(alone.n_features(), 8);
/// let u = ndarray::Array2::<f64>::ones((100, 1));
/// assert!(alone.compress(u.view(), u.view()).is_err());
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "WithLearnedFields")]
pub struct WithLearned {
    inner: Option<Box<CompressorConfig>>,
    shape: LearnedShape,
    network: Option<SummaryNetwork>,
}

/// A learned stage 1 as a file stores it, checked as
/// [`WithLearned::new`] and [`WithLearned::with_network`] check it.
#[derive(Deserialize)]
struct WithLearnedFields {
    inner: Option<Box<CompressorConfig>>,
    shape: LearnedShape,
    network: Option<SummaryNetwork>,
}

impl TryFrom<WithLearnedFields> for WithLearned {
    type Error = CompressError;
    fn try_from(f: WithLearnedFields) -> Result<Self> {
        let unchecked = Self::new(f.inner.map(|i| *i), f.shape)?;
        match f.network {
            Some(network) => unchecked.with_network(network),
            None => Ok(unchecked),
        }
    }
}

impl WithLearned {
    /// `inner`'s features (when given), then the summary of an untrained
    /// network of `shape`.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for an impossible shape or an
    /// inner compressor that already learns.
    pub fn new(inner: Option<CompressorConfig>, shape: LearnedShape) -> Result<Self> {
        shape.check()?;
        if let Some(CompressorConfig::Learned(_)) = inner {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "learned",
                value: inner.map_or_else(String::new, |i| i.to_string()),
                reason: "one `+learned`, last".into(),
            }));
        }
        Ok(Self {
            inner: inner.map(Box::new),
            shape,
            network: None,
        })
    }

    /// The same with `network` trained: its last layer must have the
    /// shape's channels.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for a network of other channels.
    pub fn with_network(mut self, network: SummaryNetwork) -> Result<Self> {
        let channels: Vec<usize> = network.layers.iter().map(|l| l.outputs).collect();
        if channels != self.shape.channels {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "summary network",
                value: format!("channels {channels:?}"),
                reason: format!("the specification asks for {:?}", self.shape.channels),
            }));
        }
        self.network = Some(network);
        Ok(self)
    }

    /// The compressor whose features come first, if any.
    pub fn inner(&self) -> Option<&CompressorConfig> {
        self.inner.as_deref()
    }

    /// The same with its inner compressor replaced (shaped or prepared).
    pub(crate) fn with_inner(&self, inner: Option<CompressorConfig>) -> Self {
        Self {
            inner: inner.map(Box::new),
            shape: self.shape.clone(),
            network: self.network.clone(),
        }
    }

    /// The architecture asked for.
    pub fn shape(&self) -> &LearnedShape {
        &self.shape
    }

    /// The trained network, once trained.
    pub fn network(&self) -> Option<&SummaryNetwork> {
        self.network.as_ref()
    }

    /// The specification, `SPEC+learned:C,..` or `learned:C,..`, when the
    /// inner one has one.
    pub fn spec(&self) -> Option<String> {
        let own = format!("learned:{}", self.shape.spec());
        match &self.inner {
            Some(inner) => Some(format!("{}+{own}", inner.spec()?)),
            None => Some(own),
        }
    }

    fn inner_features(&self) -> usize {
        self.inner.as_ref().map_or(0, |i| i.n_features())
    }

    fn appended(&self) -> usize {
        2 * self.shape.channels.last().copied().unwrap_or(0)
    }

    /// The inner features (by its estimate-time path when `fast`), then
    /// the summary; the network's pass is the same either way.
    fn compress_by(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
        fast: bool,
    ) -> Result<()> {
        let (features, summary) =
            super::split_appended(alpha, self.inner_features(), self.appended())?;
        match &self.inner {
            Some(inner) if fast => inner.compress_fast_into(inputs, outputs, work, features)?,
            Some(inner) => inner.compress_into(inputs, outputs, work, features)?,
            None => {}
        }
        self.summary_into(inputs, outputs, work, summary)
    }

    fn summary_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        summary: &mut [f64],
    ) -> Result<()> {
        let network = self.network.as_ref().ok_or_else(|| {
            CompressError::InvalidSetting(InvalidSetting {
                name: "learned",
                value: self.spec().unwrap_or_default(),
                reason: "the summary network is trained with the estimator: train one \
                         (`twostage train --compress ...+learned`) and compress through it"
                    .into(),
            })
        })?;
        network.summarize(inputs, outputs, work, summary)
    }
}

impl fmt::Display for WithLearned {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(inner) = &self.inner {
            write!(f, "{inner} and ")?;
        }
        write!(
            f,
            "a learned summary ({} channels, kernel {}, stride {}",
            self.shape.spec(),
            self.shape.kernel,
            self.shape.stride,
        )?;
        match &self.network {
            Some(network) => write!(
                f,
                "; {} weights, records of {} samples or more)",
                network.weights.len(),
                network.min_samples()
            ),
            None => write!(f, ", untrained)"),
        }
    }
}

impl Compressor for WithLearned {
    fn n_features(&self) -> usize {
        self.inner_features() + self.appended()
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.compress_by(inputs, outputs, work, alpha, false)
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.compress_by(inputs, outputs, work, alpha, true)
    }

    fn feature_names(&self) -> Vec<String> {
        let mut names = self
            .inner
            .as_ref()
            .map_or_else(Vec::new, |i| i.feature_names());
        let channels = self.appended() / 2;
        names.extend((0..channels).map(|c| format!("learned_mean_{c}")));
        names.extend((0..channels).map(|c| format!("learned_square_{c}")));
        names
    }
}

/// Parses `learned` or `learned:C1,C2,..` (the channels).
pub(crate) fn parse_shape(part: &str) -> Option<Result<LearnedShape>> {
    let part = part.trim();
    if part == "learned" {
        return Some(Ok(LearnedShape::default()));
    }
    let channels = part.strip_prefix("learned:")?;
    let parsed: Option<Vec<usize>> = channels.split(',').map(|c| c.trim().parse().ok()).collect();
    Some(match parsed {
        Some(channels) => {
            let shape = LearnedShape {
                channels,
                ..LearnedShape::default()
            };
            shape.check().map(|()| shape)
        }
        None => Err(CompressError::InvalidSetting(InvalidSetting {
            name: "learned",
            value: part.to_string(),
            reason: "channels are whole numbers separated by commas (learned:8,8,8)".into(),
        })),
    })
}

#[cfg(test)]
mod tests;
