//! The learned stage 1's arithmetic: strided one-dimensional convolutions
//! with tanh over channel-major signals, and the pooling of the last
//! layer into its time averages and the averages of its squares.
//!
//! The host's summary network, its training and the runtime call these
//! same functions, so a record's summary has the same bits everywhere:
//! the host over whole arrays, the runtime position by position as the
//! samples stream in.

use crate::Values;

/// One strided convolution: `out[o][t] = tanh(b[o] + sum_c sum_k
/// w[o][c][k] in[c][stride t + k])` over the positions where the kernel
/// fits (no padding).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ConvShape {
    /// Channels in (the signals, for the first layer).
    pub inputs: usize,
    /// Channels out.
    pub outputs: usize,
    /// Kernel width in samples.
    pub kernel: usize,
    /// Samples between successive positions.
    pub stride: usize,
}

impl ConvShape {
    /// Weights of the layer: `outputs x inputs x kernel` taps, then
    /// `outputs` biases.
    pub const fn n_weights(&self) -> usize {
        self.outputs * (self.inputs * self.kernel + 1)
    }

    /// Positions the kernel takes over `length` samples (0 if it does not
    /// fit, or for a zero stride).
    pub const fn positions(&self, length: usize) -> usize {
        if length < self.kernel || self.stride == 0 {
            0
        } else {
            (length - self.kernel) / self.stride + 1
        }
    }
}

/// The shortest record that leaves the last of `layers` at least one
/// position.
///
/// ```
/// use twostage_kernels::convolution::{ConvShape, min_samples};
/// let layer = |inputs| ConvShape { inputs, outputs: 4, kernel: 5, stride: 2 };
/// // 5 samples for one layer; 2 * (5 - 1) + 5 = 13 for two.
/// assert_eq!(min_samples(&[layer(2)]), 5);
/// assert_eq!(min_samples(&[layer(2), layer(4)]), 13);
/// ```
pub fn min_samples(layers: &[ConvShape]) -> usize {
    layers
        .iter()
        .rev()
        .fold(1, |after, l| (after - 1) * l.stride + l.kernel)
}

/// Applies `shape` with `weights` (taps out x in x kernel, row-major, then
/// the biases) to `input` (channel-major, `length_in` samples a channel)
/// into `output` (channel-major), and returns the output's length. Each
/// position is [`convolve_position`]'s, so a stream that sees the samples
/// one at a time computes the same bits.
///
/// ```
/// use twostage_kernels::convolution::{ConvShape, convolve_tanh};
/// // One channel, a kernel (1, -1) with stride 1 and bias 0: tanh of differences.
/// let shape = ConvShape { inputs: 1, outputs: 1, kernel: 2, stride: 1 };
/// let mut out = [0.0; 3];
/// let length = convolve_tanh(shape, &[1.0, -1.0, 0.0], &[0.0, 1.0, 3.0, 3.0], 4, &mut out);
/// assert_eq!(length, 3);
/// assert_eq!(out, [twostage_kernels::tanh(-1.0), twostage_kernels::tanh(-2.0), 0.0]);
/// ```
///
/// Weights, input or output too short for the shape leave the output as
/// it is and return 0 (callers size them from the same shapes).
pub fn convolve_tanh(
    shape: ConvShape,
    weights: &[f64],
    input: &[f64],
    length_in: usize,
    output: &mut [f64],
) -> usize {
    let length_out = shape.positions(length_in);
    if weights.len() < shape.n_weights()
        || input.len() < shape.inputs * length_in
        || output.len() < shape.outputs * length_out
    {
        return 0;
    }
    for t in 0..length_out {
        let start = t * shape.stride;
        convolve_position(
            shape,
            weights,
            0,
            |c| &input[c * length_in + start..][..shape.kernel],
            |o, z| output[o * length_out + t] = z,
        );
    }
    length_out
}

/// One position of [`convolve_tanh`]: `emit(o, tanh(b[o] + sum_c
/// w[o][c] . window(c)))` for each output channel `o`, where `window(c)`
/// is input channel `c`'s `kernel` samples under the kernel and the
/// layer's weights start at `weights[offset]` (a slice on the host, a
/// blob's bytes in the runtime). The sum runs bias first, then channel by
/// channel, each channel's taps in index order ([`Values::dot_from`]).
///
/// ```
/// use twostage_kernels::convolution::{ConvShape, convolve_position};
/// let shape = ConvShape { inputs: 2, outputs: 1, kernel: 2, stride: 1 };
/// // Taps (1, 1) and (0, 2), bias -1.
/// let weights = [1.0, 1.0, 0.0, 2.0, -1.0];
/// let windows = [[0.5, 0.25], [0.0, 0.125]];
/// let mut z = 0.0;
/// convolve_position(shape, &weights[..], 0, |c| &windows[c][..], |_, v| z = v);
/// assert_eq!(z, twostage_kernels::tanh(-1.0 + 0.75 + 0.25));
/// ```
pub fn convolve_position<'x, W: Values + ?Sized>(
    shape: ConvShape,
    weights: &W,
    offset: usize,
    window: impl Fn(usize) -> &'x [f64],
    mut emit: impl FnMut(usize, f64),
) {
    let taps = offset + shape.outputs * shape.inputs * shape.kernel;
    for o in 0..shape.outputs {
        let mut z = weights.at(taps + o);
        for c in 0..shape.inputs {
            z += weights.dot_from(offset + (o * shape.inputs + c) * shape.kernel, window(c));
        }
        emit(o, crate::tanh(z));
    }
}

/// The time average of each of the `channels` channels of `last`
/// (channel-major, `length` samples a channel) into `out[..channels]`, and
/// the average of its square into `out[channels..2 channels]`: the sums
/// [`pool_accumulate`] keeps position by position, through
/// [`pool_finish`].
///
/// ```
/// use twostage_kernels::convolution::pool_mean_and_square;
/// let mut out = [0.0; 4];
/// pool_mean_and_square(&[1.0, -1.0, 0.5, 0.5], 2, 2, &mut out);
/// assert_eq!(out, [0.0, 0.5, 1.0, 0.25]);
/// ```
///
/// Too short a `last` or `out` leaves `out` as it is.
pub fn pool_mean_and_square(last: &[f64], channels: usize, length: usize, out: &mut [f64]) {
    if last.len() < channels * length || out.len() < 2 * channels || length == 0 {
        return;
    }
    let sums = &mut out[..2 * channels];
    sums.fill(0.0);
    for t in 0..length {
        pool_accumulate(sums, channels, |c| last[c * length + t]);
    }
    pool_finish(sums, length);
}

/// Adds one position of the last layer (`value(c)` for each of the
/// `channels` channels) to `sums`: each channel's sum, then each one's sum
/// of squares.
///
/// ```
/// use twostage_kernels::convolution::{pool_accumulate, pool_finish};
/// let mut sums = [0.0; 2];
/// pool_accumulate(&mut sums, 1, |_| 2.0);
/// pool_accumulate(&mut sums, 1, |_| -1.0);
/// pool_finish(&mut sums, 2);
/// assert_eq!(sums, [0.5, 2.5]);
/// ```
pub fn pool_accumulate(sums: &mut [f64], channels: usize, value: impl Fn(usize) -> f64) {
    let (means, squares) = sums.split_at_mut(channels.min(sums.len()));
    for (c, (m, s)) in means.iter_mut().zip(squares.iter_mut()).enumerate() {
        let v = value(c);
        *m += v;
        *s += v * v;
    }
}

/// The sums of [`pool_accumulate`] over `positions` positions, turned
/// into averages in place.
pub fn pool_finish(sums: &mut [f64], positions: usize) {
    for v in sums.iter_mut() {
        *v /= positions as f64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_two_channel_strided_layer_matches_the_sum_written_out() {
        let shape = ConvShape {
            inputs: 2,
            outputs: 1,
            kernel: 3,
            stride: 2,
        };
        // Taps: channel 0 (1, 2, 3), channel 1 (-1, 0, 1); bias 0.5.
        let weights = [1.0, 2.0, 3.0, -1.0, 0.0, 1.0, 0.5];
        let a = [0.1, 0.2, 0.3, 0.4, 0.5];
        let b = [1.0, -1.0, 2.0, -2.0, 3.0];
        let mut input = [0.0; 10];
        input[..5].copy_from_slice(&a);
        input[5..].copy_from_slice(&b);
        let mut out = [9.0; 3];
        assert_eq!(convolve_tanh(shape, &weights, &input, 5, &mut out), 2);
        for (t, got) in out[..2].iter().enumerate() {
            let s = 2 * t;
            let z = 0.5 + (a[s] + 2.0 * a[s + 1] + 3.0 * a[s + 2]) + (-b[s] + b[s + 2]);
            assert!((got - z.tanh()).abs() < 1e-15, "{t}: {got} {}", z.tanh());
        }
        // The position the kernel does not fit is not written.
        assert_eq!(out[2].to_bits(), 9.0f64.to_bits());
    }

    #[test]
    fn short_buffers_write_nothing() {
        let shape = ConvShape {
            inputs: 1,
            outputs: 2,
            kernel: 2,
            stride: 1,
        };
        let mut out = [7.0; 4];
        assert_eq!(convolve_tanh(shape, &[1.0; 5], &[1.0; 3], 3, &mut out), 0);
        assert!(out.iter().all(|v| v.to_bits() == 7.0f64.to_bits()));
        let mut pooled = [7.0; 2];
        pool_mean_and_square(&[1.0], 1, 2, &mut pooled);
        assert!(pooled.iter().all(|v| v.to_bits() == 7.0f64.to_bits()));
    }
}
