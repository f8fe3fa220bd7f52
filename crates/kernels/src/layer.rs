//! One dense layer of a feed-forward network: `out = act(W x + b)`.

use crate::Values;

/// The layer's activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    /// `tanh`, the hidden layers'.
    Tanh,
    /// None, the output layer's.
    Identity,
}

/// `out[i] = act(bias[i] + sum_c weights[i * n_in + c] input[c])` for
/// `i < out.len()`, with `n_in = input.len()`; the sum runs in index order.
/// The weights and biases are any [`Values`]: a slice, or an exported
/// estimator's bytes read in place.
///
/// ```
/// use twostage_kernels::layer::{Activation, dense_layer};
/// let mut out = [0.0; 2];
/// dense_layer(&[1.0, 2.0, 0.0, -1.0][..], &[0.5, 0.0][..], &[3.0, 4.0], Activation::Identity, &mut out);
/// assert_eq!(out, [11.5, -4.0]);
/// ```
///
/// Weights or bias shorter than the layer leave the remaining outputs
/// untouched (callers size them from the same layer sizes).
#[inline]
pub fn dense_layer<W, B>(
    weights: &W,
    bias: &B,
    input: &[f64],
    activation: Activation,
    out: &mut [f64],
) where
    W: Values + ?Sized,
    B: Values + ?Sized,
{
    let n_in = input.len().max(1);
    let rows = (weights.len() / n_in).min(bias.len());
    for (i, o) in out.iter_mut().enumerate().take(rows) {
        let z = bias.at(i) + weights.dot_from(i * n_in, input);
        *o = match activation {
            Activation::Tanh => crate::tanh(z),
            Activation::Identity => z,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_layer_matches_the_definition() {
        let w = [0.3, -0.2, 0.1, 0.4, 0.0, -0.5];
        let b = [0.1, -0.1];
        let x = [1.0, 2.0, -1.0];
        let mut out = [0.0; 2];
        dense_layer(&w[..], &b[..], &x, Activation::Tanh, &mut out);
        let z0: f64 = 0.1 + 0.3 - 0.4 - 0.1;
        let z1: f64 = -0.1 + 0.4 + 0.0 + 0.5;
        assert!((out[0] - z0.tanh()).abs() < 1e-15 && (out[1] - z1.tanh()).abs() < 1e-15);
    }
}
