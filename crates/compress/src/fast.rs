//! The estimate-time fast path of ARX: the normal-equation entries of
//! eq. (2) are lagged correlations of the signals, so they cost one dot
//! product per distinct (signal pair, lag difference) instead of N x n^2
//! products, and the n x n system is solved by Cholesky. The arithmetic is
//! the kernels crate's (`twostage_kernels::lagged`); this module adds the
//! SIMD dot product and the scratch space.
//!
//! Normal equations square the condition number, so the fast path answers
//! directly only when the Cholesky pivots show a well-conditioned problem
//! (`L_jj >= FAST_PIVOT_TOLERANCE * sqrt(G_jj)`, the same angle measure as
//! the QR rank check), with iterative refinement down to
//! `REFINED_PIVOT_TOLERANCE` (a smooth input such as the car's chicane),
//! and otherwise hands over to QR, which gives the exact answer or the
//! precise error. Tests check agreement with QR to 1e-9.

use ndarray::ArrayView2;
use twostage_kernels::VectorOps;
use twostage_kernels::lagged::{
    Conditioning, LaggedBuffers, LaggedColumn, lagged_least_squares as solve,
};

/// Smallest accepted `L_jj / sqrt(G_jj)` (the sine of the angle between a
/// regressor and the span of the previous ones): at 1e-3 the Gram matrix
/// has a condition number of at most about 1e6 n, so the coefficients keep
/// at least nine correct digits.
pub(crate) const FAST_PIVOT_TOLERANCE: f64 = 1e-3;

/// Smallest sine answered with iterative refinement: the normal matrix's
/// condition number is then at most about 1e12 n, so each refinement step
/// shrinks the error by about 1e-4 n and a few settle it; below this the
/// Cholesky pivots themselves lose their meaning, and QR decides.
pub(crate) const REFINED_PIVOT_TOLERANCE: f64 = 1e-6;

/// Scratch space of the fast path (kept inside [`crate::Workspace`]).
#[derive(Debug, Default, Clone)]
pub(crate) struct FastScratch {
    gram: Vec<f64>,
    /// Full-length correlations, memoized per (signal a, signal b, lag d).
    table: Vec<f64>,
    /// The refinement's residual and correction.
    residual: Vec<f64>,
    correction: Vec<f64>,
}

/// Dot product of two equally long slices, with the widest SIMD the
/// processor offers (pulp dispatches at run time, safely) and four
/// independent vector accumulators. The summation order is fixed for a
/// given processor, so results are reproducible on it.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    struct Dot<'a>(&'a [f64], &'a [f64]);
    impl pulp::WithSimd for Dot<'_> {
        type Output = f64;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) -> f64 {
            let n = self.0.len().min(self.1.len());
            let (a, a_tail) = S::as_simd_f64s(&self.0[..n]);
            let (b, b_tail) = S::as_simd_f64s(&self.1[..n]);
            let zero = simd.splat_f64s(0.0);
            let mut acc = [zero; 4];
            let (a4, b4) = (a.chunks_exact(4), b.chunks_exact(4));
            let (a_rest, b_rest) = (a4.remainder(), b4.remainder());
            for (x, y) in a4.zip(b4) {
                for j in 0..4 {
                    acc[j] = simd.mul_add_e_f64s(x[j], y[j], acc[j]);
                }
            }
            for (x, y) in a_rest.iter().zip(b_rest) {
                acc[0] = simd.mul_add_e_f64s(*x, *y, acc[0]);
            }
            let sum = simd.add_f64s(simd.add_f64s(acc[0], acc[1]), simd.add_f64s(acc[2], acc[3]));
            let tail: f64 = a_tail.iter().zip(b_tail).map(|(x, y)| x * y).sum();
            simd.reduce_sum_f64s(sum) + tail
        }
    }
    if a.len().min(b.len()) < 32 {
        // The window corrections are a few terms: not worth a dispatch.
        return a.iter().zip(b).map(|(x, y)| x * y).sum();
    }
    pulp::Arch::new().dispatch(Dot(a, b))
}

/// `r[k] -= x v[k]` with the widest SIMD the processor offers, one
/// multiply-add per element (fused where the processor has FMA).
fn subtract_scaled(r: &mut [f64], x: f64, v: &[f64]) {
    struct Update<'a>(&'a mut [f64], f64, &'a [f64]);
    impl pulp::WithSimd for Update<'_> {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, simd: S) {
            let n = self.0.len().min(self.2.len());
            let minus_x = -self.1;
            let (r, r_tail) = S::as_mut_simd_f64s(&mut self.0[..n]);
            let (v, v_tail) = S::as_simd_f64s(&self.2[..n]);
            let scale = simd.splat_f64s(minus_x);
            for (r, v) in r.iter_mut().zip(v) {
                *r = simd.mul_add_e_f64s(scale, *v, *r);
            }
            for (r, v) in r_tail.iter_mut().zip(v_tail) {
                *r = minus_x.mul_add(*v, *r);
            }
        }
    }
    pulp::Arch::new().dispatch(Update(r, x, v));
}

/// The host's vector arithmetic for the kernels: SIMD dot products and
/// updates.
struct SimdOps;

impl VectorOps for SimdOps {
    fn dot(&self, a: &[f64], b: &[f64]) -> f64 {
        dot(a, b)
    }
    fn subtract_scaled(&self, r: &mut [f64], x: f64, v: &[f64]) {
        subtract_scaled(r, x, v);
    }
}

/// Solve the least-squares problem whose regressors are `columns` of
/// `signals` over samples `start..N` and whose target is `signals[0]`,
/// writing the coefficients into `alpha`, by the kernels' lagged normal
/// equations with this crate's SIMD dot product. Returns false (and leaves
/// `alpha` unspecified) when the fast path cannot vouch for the answer.
pub(crate) fn lagged_least_squares(
    signals: &[&[f64]],
    columns: &[LaggedColumn],
    start: usize,
    max_lag: usize,
    scratch: &mut FastScratch,
    alpha: &mut [f64],
) -> bool {
    let n = columns.len();
    scratch
        .table
        .resize(signals.len() * signals.len() * (max_lag + 1), 0.0);
    scratch.gram.resize(n * n, 0.0);
    let samples = signals.first().map_or(0, |s| s.len());
    scratch.residual.resize(samples.saturating_sub(start), 0.0);
    scratch.correction.resize(n, 0.0);
    let buffers = LaggedBuffers {
        table: &mut scratch.table,
        gram: &mut scratch.gram,
        solution: alpha,
        residual: &mut scratch.residual,
        correction: &mut scratch.correction,
    };
    let conditioning = Conditioning {
        direct: FAST_PIVOT_TOLERANCE,
        refined: REFINED_PIVOT_TOLERANCE,
    };
    solve(
        signals,
        columns,
        start,
        max_lag,
        conditioning,
        &SimdOps,
        buffers,
    )
    .is_ok()
}

/// Contiguous column `j` of a view, if it is one.
pub(crate) fn contiguous_column<'a>(view: &ArrayView2<'a, f64>, j: usize) -> Option<&'a [f64]> {
    (*view).index_axis_move(ndarray::Axis(1), j).to_slice()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Arx, Compressor};
    use ndarray::Array2;

    /// A deterministic, well-mixed test signal.
    fn signal(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    fn solve(u: &[f64], y: &[f64], na: usize, nb: usize) -> (bool, Vec<f64>) {
        let columns: Vec<LaggedColumn> = (1..=na)
            .map(|lag| LaggedColumn { signal: 0, lag })
            .chain((1..=nb).map(|lag| LaggedColumn { signal: 1, lag }))
            .collect();
        let start = na.max(nb);
        let mut alpha = vec![0.0; na + nb];
        let ok = lagged_least_squares(
            &[y, u],
            &columns,
            start,
            start,
            &mut FastScratch::default(),
            &mut alpha,
        );
        (ok, alpha)
    }

    /// The ARX(order, order) coefficients by the QR path, the reference.
    fn qr_solution(u: Vec<f64>, y: Vec<f64>, order: usize) -> Vec<f64> {
        let n = u.len();
        let (u, y) = (
            Array2::from_shape_vec((n, 1), u).unwrap(),
            Array2::from_shape_vec((n, 1), y).unwrap(),
        );
        Arx::new(order, order)
            .unwrap()
            .compress(u.view(), y.view())
            .unwrap()
    }

    #[test]
    fn answers_well_conditioned_problems_and_matches_qr() {
        let n = 1000;
        let u = signal(n, 1);
        let e = signal(n, 2);
        let mut y = vec![0.0; n];
        for t in 2..n {
            y[t] = 0.6 * y[t - 1] - 0.1 * y[t - 2] + u[t - 1] + 0.3 * e[t];
        }
        let (ok, fast) = solve(&u, &y, 5, 5);
        assert!(ok, "the fast path declined a well-conditioned problem");
        let qr = qr_solution(u, y, 5);
        for (f, q) in fast.iter().zip(&qr) {
            assert!(
                (f - q).abs() < 1e-11 * q.abs().max(1.0),
                "{fast:?} vs {qr:?}"
            );
        }
    }

    #[test]
    fn refines_a_smooth_input_and_matches_qr() {
        // A chicane-like steering input sampled finely: its four lags are
        // nearly collinear (coefficients in the thousands), beyond the
        // direct answer; the refined one agrees with QR.
        let n = 500;
        let u: Vec<f64> = (0..n)
            .map(|k| {
                let t = 0.02 * k as f64;
                (-(t - 4.0).powi(2)).exp() - (-(t - 6.0).powi(2)).exp()
            })
            .collect();
        let e = signal(n, 3);
        let mut y = vec![0.0; n];
        for t in 2..n {
            y[t] = 1.7 * y[t - 1] - 0.72 * y[t - 2] + 0.3 * u[t - 1] + 1e-3 * e[t];
        }
        let (ok, fast) = solve(&u, &y, 4, 4);
        assert!(ok, "the fast path declined a smooth input it can refine");
        let qr = qr_solution(u, y, 4);
        let size = qr.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (f, q) in fast.iter().zip(&qr) {
            assert!((f - q).abs() <= 1e-9 * size, "{fast:?} vs {qr:?}");
        }
    }

    #[test]
    fn declines_nearly_collinear_regressors() {
        let n = 500;
        let u: Vec<f64> = (0..n).map(|k| (0.01 * k as f64).sin()).collect();
        let y: Vec<f64> = (0..n).map(|k| (0.013 * k as f64).cos()).collect();
        assert!(!solve(&u, &y, 2, 3).0);
    }

    #[test]
    fn the_simd_update_is_one_multiply_add_per_element() {
        // Lengths around every vector width, element by element: a fused
        // multiply-add, or the plain one on a processor without FMA.
        for n in [0usize, 1, 3, 4, 7, 8, 9, 31, 64, 67] {
            let v = signal(n, 5);
            let start = signal(n, 6);
            let mut r = start.clone();
            subtract_scaled(&mut r, 0.37, &v);
            for k in 0..n {
                let fused = (-0.37f64).mul_add(v[k], start[k]);
                let plain = start[k] - 0.37 * v[k];
                assert!(r[k].to_bits() == fused.to_bits() || r[k].to_bits() == plain.to_bits());
            }
        }
    }

    #[test]
    fn dot_sums_every_term() {
        let a: Vec<f64> = (0..19).map(f64::from).collect();
        let b = vec![1.0; 19];
        assert!((dot(&a, &b) - 171.0).abs() < 1e-12);
        assert!(dot(&[], &[]).abs() < 1e-300);
    }
}
