//! One dense layer of a feed-forward network: `out = act(W x + b)`.

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
///
/// ```
/// use twostage_kernels::layer::{Activation, dense_layer};
/// let mut out = [0.0; 2];
/// dense_layer(&[1.0, 2.0, 0.0, -1.0], &[0.5, 0.0], &[3.0, 4.0], Activation::Identity, &mut out);
/// assert_eq!(out, [11.5, -4.0]);
/// ```
///
/// Weights or bias shorter than the layer leave the remaining outputs
/// untouched (callers size them from the same layer sizes).
#[inline]
pub fn dense_layer(
    weights: &[f64],
    bias: &[f64],
    input: &[f64],
    activation: Activation,
    out: &mut [f64],
) {
    let n_in = input.len();
    for ((o, row), b) in out
        .iter_mut()
        .zip(weights.chunks_exact(n_in.max(1)))
        .zip(bias)
    {
        let z = b + crate::dot(row, input);
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
        dense_layer(&w, &b, &x, Activation::Tanh, &mut out);
        let z0: f64 = 0.1 + 0.3 - 0.4 - 0.1;
        let z1: f64 = -0.1 + 0.4 + 0.0 + 0.5;
        assert!((out[0] - z0.tanh()).abs() < 1e-15 && (out[1] - z1.tanh()).abs() < 1e-15);
    }
}
