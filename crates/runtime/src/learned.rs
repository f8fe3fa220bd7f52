//! A learned stage 1 streamed: the summary network's convolutions run
//! position by position as the samples come, each layer keeping only the
//! last kernel's worth of its input, and the last layer's activations are
//! pooled into running sums. The arithmetic is the host's
//! ([`twostage_kernels::convolution`]), in the host's order, so a record's
//! summary has the host's bits.

use twostage_kernels::Values;
use twostage_kernels::convolution::{
    ConvShape, convolve_position, min_samples, pool_accumulate, pool_finish,
};

use crate::bytes::{Cursor, LeF64s, u32_at};
use crate::error::Error;
use crate::format::{MAX_CHANNELS, MAX_KERNEL, MAX_LAYERS};

/// The network of a blob, read in place.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Learned<'a> {
    /// Per layer: channels out, kernel, stride (`u32`).
    shapes: &'a [u8],
    layers: usize,
    signals: usize,
    scales: LeF64s<'a>,
    weights: LeF64s<'a>,
}

impl<'a> Learned<'a> {
    /// Reads and checks the section (format version 4) for `signals`
    /// signals, inputs first: shapes within the runtime's limits, finite
    /// weights, positive scales.
    pub(crate) fn read(c: &mut Cursor<'a>, signals: usize) -> Result<Self, Error> {
        let learned = Self::parse(c, signals)?;
        if !learned.weights.all_finite() {
            return Err(Error::Invalid {
                field: "learned weight",
                at: c.at - 8 * learned.weights.len(),
            });
        }
        if (0..signals).any(|j| !(learned.scales.at(j).is_finite() && learned.scales.at(j) > 0.0)) {
            return Err(Error::Invalid {
                field: "learned signal scale",
                at: c.at - 8 * (learned.weights.len() + signals),
            });
        }
        Ok(learned)
    }

    /// The section's shapes checked and its numbers found, not read: what
    /// a stream does with a network its load checked.
    pub(crate) fn parse(c: &mut Cursor<'a>, signals: usize) -> Result<Self, Error> {
        let at = c.at;
        let layers = c.count("learned layer count", MAX_LAYERS)?;
        let shapes_at = c.at;
        let shapes = c.u32s(3 * layers)?;
        if layers == 0 || signals == 0 || signals > MAX_CHANNELS {
            return Err(Error::Invalid {
                field: "learned layer count",
                at,
            });
        }
        let mut learned = Self {
            shapes,
            layers,
            signals,
            scales: LeF64s::default(),
            weights: LeF64s::default(),
        };
        let mut n_weights = 0usize;
        for l in 0..layers {
            let fits = learned.layer(l).is_some_and(|shape| {
                (1..=MAX_CHANNELS).contains(&shape.outputs)
                    && (1..=MAX_KERNEL).contains(&shape.kernel)
                    && (1..=shape.kernel).contains(&shape.stride)
            });
            if !fits {
                return Err(Error::Invalid {
                    field: "learned layer shape",
                    at: shapes_at + 12 * l,
                });
            }
            // At most 6 layers of 32 x 32 x 64 taps: no overflow.
            n_weights += learned.layer(l).map_or(0, |shape| shape.n_weights());
        }
        learned.scales = c.f64s(signals)?;
        learned.weights = c.f64s(n_weights)?;
        Ok(learned)
    }

    /// Layer `l`'s shape, its inputs the signals or the layer before's
    /// channels; `None` past the end.
    fn layer(&self, l: usize) -> Option<ConvShape> {
        if l >= self.layers {
            return None;
        }
        let field = |l: usize, k: usize| u32_at(self.shapes, 4 * (3 * l + k)).map(|v| v as usize);
        let inputs = match l {
            0 => self.signals,
            _ => field(l - 1, 0)?,
        };
        Some(ConvShape {
            inputs,
            outputs: field(l, 0)?,
            kernel: field(l, 1)?,
            stride: field(l, 2)?,
        })
    }

    fn shapes(&self) -> impl Iterator<Item = ConvShape> + '_ {
        (0..self.layers).map_while(|l| self.layer(l))
    }

    /// Channels of the last layer.
    fn channels(&self) -> usize {
        self.layer(self.layers.saturating_sub(1))
            .map_or(0, |l| l.outputs)
    }

    /// Its summary numbers: each last channel's average, then each one's
    /// average square.
    pub(crate) fn n_features(&self) -> usize {
        2 * self.channels()
    }

    /// The shortest record that leaves the last layer one position.
    pub(crate) fn min_samples(&self) -> usize {
        let mut shapes = [ConvShape {
            inputs: 0,
            outputs: 0,
            kernel: 0,
            stride: 0,
        }; MAX_LAYERS];
        for (slot, shape) in shapes.iter_mut().zip(self.shapes()) {
            *slot = shape;
        }
        min_samples(shapes.get(..self.layers).unwrap_or_default())
    }

    /// Words of a stream's state: per layer the count of its inputs and a
    /// ring of each input channel's last kernel samples, kept twice so
    /// that a kernel's window is one run; then the positions pooled and
    /// the pooled sums.
    pub(crate) fn state_words(&self) -> usize {
        self.shapes()
            .map(|l| 1 + 2 * l.inputs * l.kernel)
            .sum::<usize>()
            + 1
            + self.n_features()
    }

    /// Takes one sample (`sample(j)` for signal j, inputs first, as
    /// measured) into `state`: divided by its signal's scale, through
    /// each layer whose kernel it completes, into the pooled sums.
    pub(crate) fn push(&self, state: &mut [f64], sample: impl Fn(usize) -> f64) {
        let mut values = [0.0; MAX_CHANNELS];
        for (j, v) in values.iter_mut().enumerate().take(self.signals) {
            *v = sample(j) / self.scales.at(j);
        }
        let (mut at, mut offset) = (0, 0);
        for shape in self.shapes() {
            let words = 1 + 2 * shape.inputs * shape.kernel;
            let Some(layer) = state.get_mut(at..at + words) else {
                return;
            };
            at += words;
            let Some((count, ring)) = layer.split_first_mut() else {
                return;
            };
            let k = shape.kernel;
            let taken = *count as usize;
            let slot = taken % k;
            for (channel, v) in ring.chunks_exact_mut(2 * k).zip(&values) {
                for i in [slot, slot + k] {
                    if let Some(kept) = channel.get_mut(i) {
                        *kept = *v;
                    }
                }
            }
            let taken = taken + 1;
            *count = taken as f64;
            if taken < k || !(taken - k).is_multiple_of(shape.stride) {
                return;
            }
            // The last k samples are the run from `taken % k`.
            let start = taken % k;
            let ring: &[f64] = ring;
            let mut next = [0.0; MAX_CHANNELS];
            convolve_position(
                shape,
                &self.weights,
                offset,
                |c| {
                    ring.get(c * 2 * k + start..c * 2 * k + start + k)
                        .unwrap_or_default()
                },
                |o, z| {
                    if let Some(slot) = next.get_mut(o) {
                        *slot = z;
                    }
                },
            );
            offset += shape.n_weights();
            values = next;
        }
        let channels = self.channels();
        if let Some((positions, sums)) = state.get_mut(at..).and_then(|s| s.split_first_mut()) {
            *positions += 1.0;
            pool_accumulate(sums, channels, |c| {
                values.get(c).copied().unwrap_or(f64::NAN)
            });
        }
    }

    /// The summary of the samples `state` took, into `out`
    /// ([`Self::n_features`] numbers); `false` while the last layer has
    /// no position yet.
    pub(crate) fn finish(&self, state: &[f64], out: &mut [f64]) -> bool {
        let at = self.state_words() - 1 - self.n_features();
        let Some((positions, sums)) = state.get(at..).and_then(|s| s.split_first()) else {
            return false;
        };
        if *positions < 1.0 {
            return false;
        }
        for (o, s) in out.iter_mut().zip(sums.iter().take(self.n_features())) {
            *o = *s;
        }
        pool_finish(out, *positions as usize);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use twostage_kernels::convolution::{convolve_tanh, pool_mean_and_square};

    /// Two layers over two signals, as a blob's section lays them out.
    fn section(weights: &[f64]) -> std::vec::Vec<u8> {
        let mut bytes = std::vec::Vec::new();
        for v in [2u32, 3, 3, 2, 2, 2, 1] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&[0; 4]);
        for v in [0.5f64, 2.0].iter().chain(weights) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes
    }

    extern crate std;

    #[test]
    fn a_streamed_record_has_the_bits_of_the_whole_arrays() {
        let first = ConvShape {
            inputs: 2,
            outputs: 3,
            kernel: 3,
            stride: 2,
        };
        let second = ConvShape {
            inputs: 3,
            outputs: 2,
            kernel: 2,
            stride: 1,
        };
        let n_weights = first.n_weights() + second.n_weights();
        let weights: std::vec::Vec<f64> = (0..n_weights)
            .map(|i| 0.3 * libm::sin(1.7 * i as f64))
            .collect();
        let bytes = section(&weights);
        let learned = Learned::read(&mut Cursor::new(&bytes, 0), 2).unwrap();
        assert_eq!(
            (learned.n_features(), learned.min_samples()),
            (4, 5),
            "(2 - 1) * 2 + 3 samples"
        );
        let n = 23;
        let signal = |j: usize, t: usize| libm::cos(0.37 * t as f64 + j as f64) * (1.0 + j as f64);
        let mut state = std::vec![0.0; learned.state_words()];
        let mut streamed = [0.0; 4];
        for t in 0..n {
            learned.push(&mut state, |j| signal(j, t));
            assert_eq!(learned.finish(&state, &mut streamed), t + 1 >= 5, "{t}");
        }
        // The whole record at once, channel-major and scaled.
        let scaled: std::vec::Vec<f64> = (0..2)
            .flat_map(|j| (0..n).map(move |t| signal(j, t) / [0.5, 2.0][j]))
            .collect();
        let mut hidden = std::vec![0.0; 3 * first.positions(n)];
        let m = convolve_tanh(first, &weights, &scaled, n, &mut hidden);
        let mut last = std::vec![0.0; 2 * second.positions(m)];
        let m = convolve_tanh(second, &weights[first.n_weights()..], &hidden, m, &mut last);
        let mut whole = [0.0; 4];
        pool_mean_and_square(&last, 2, m, &mut whole);
        for (s, w) in streamed.iter().zip(&whole) {
            assert_eq!(s.to_bits(), w.to_bits(), "{streamed:?} {whole:?}");
        }
    }

    #[test]
    fn impossible_shapes_and_scales_are_refused() {
        let good = section(&[0.0; 21 + 14]);
        assert!(Learned::read(&mut Cursor::new(&good, 0), 2).is_ok());
        // A stride beyond its kernel, a zero scale, a weight missing.
        let mut stride = good.clone();
        stride[12..16].copy_from_slice(&4u32.to_le_bytes());
        let mut scale = good.clone();
        scale[32..40].copy_from_slice(&0.0f64.to_le_bytes());
        for bad in [stride, scale, good[..good.len() - 8].to_vec()] {
            assert!(Learned::read(&mut Cursor::new(&bad, 0), 2).is_err());
        }
    }
}
