//! The Gauss-Newton products `J'J` and `J'r` of the training's least
//! squares, by either of two computations of the same numbers:
//!
//! - from the Jacobian itself, one row per sample and target, for any
//!   network;
//! - from the structure of a network with one hidden layer, whose `q`
//!   outputs share it: every first-layer block of `J'J` is one Gram matrix
//!   of a row per sample, weighted by the output weights' own Gram matrix,
//!   and the output layer's blocks are the hidden activations' Gram matrix.
//!   Its cost does not grow with the number of targets, so it is chosen
//!   from two targets on.
//!
//! Every product is summed over the samples in one fixed order by tiles
//! that run in parallel, so the result does not depend on the number of
//! threads.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::network::{Problem, parameter_count};

/// Rows of a product per parallel task (the gradient's `J'r`, the cross
/// terms): each task sums over every sample in one fixed order.
pub(super) const GRAM_TILE: usize = 16;

/// Columns of an `n x n` Gram matrix per parallel task: each task owns its
/// columns' lower part and sums over every sample in one fixed order.
/// Each task packs the rows below its first column again, so narrow tiles
/// spend their time copying; wide ones leave the cores unevenly loaded.
/// About `n / 6` columns, a multiple of 16 from 16 to 96, balances the
/// two. It depends on `n` alone, never on the thread count, so neither do
/// the products' bits.
pub(super) fn gram_tile(n: usize) -> usize {
    (16 * ((n + 48) / 96)).clamp(16, 96)
}

/// The lower triangle of `scale A A'` for `a` (features x samples), by
/// tiles of [`gram_tile`] columns in parallel.
fn lower_gram(a: MatRef<'_, f64>, scale: f64, out: MatMut<'_, f64>) {
    let n = a.nrows();
    let width = gram_tile(n);
    out.par_col_chunks_mut(width)
        .enumerate()
        .for_each(|(tile, columns)| {
            let first = tile * width;
            let width = columns.ncols();
            matmul(
                columns.subrows_mut(first, n - first),
                Accum::Replace,
                a.subrows(first, n - first),
                a.subrows(first, width).transpose(),
                scale,
                Par::Seq,
            );
        });
}

/// The lower triangle of `scale J'J` and `scale J'r` from `J'` (n x rows,
/// column-major) and `r`, by tiles of columns in parallel.
pub(super) fn gram_products(
    jt: &[f64],
    res: &[f64],
    scale: f64,
    jtj: &mut Mat<f64>,
    jtr: &mut Mat<f64>,
) {
    let n = jtj.nrows();
    let rows = res.len();
    let jt = MatRef::from_column_major_slice(jt, n, rows);
    let res = MatRef::from_column_major_slice(res, rows, 1);
    lower_gram(jt, scale, jtj.as_mut());
    tiled_product(jt, res, scale, jtr.as_mut());
}

/// `out = scale A B` by tiles of [`GRAM_TILE`] rows in parallel, each one
/// product over every column of `a` in one order.
fn tiled_product(a: MatRef<'_, f64>, b: MatRef<'_, f64>, scale: f64, out: MatMut<'_, f64>) {
    out.par_row_chunks_mut(GRAM_TILE)
        .enumerate()
        .for_each(|(tile, rows)| {
            let first = tile * GRAM_TILE;
            let width = rows.nrows();
            matmul(
                rows,
                Accum::Replace,
                a.subrows(first, width),
                b,
                scale,
                Par::Seq,
            );
        });
}

/// Whether the products are cheaper from the structure of a network with
/// these layer sizes: one hidden layer and at least two targets (with
/// one, both computations cost the same, and the Jacobian's is kept).
pub(super) fn by_structure(sizes: &[usize]) -> bool {
    sizes.len() == 3 && sizes[2] >= 2
}

/// The entries a restart's products keep per training sample: the
/// Jacobian's row per target, or the structure's `s (x) [x; 1]`, `[z; 1]`
/// and residuals.
pub(super) fn entries_per_sample(sizes: &[usize]) -> usize {
    if by_structure(sizes) {
        let (d, h, q) = (sizes[0], sizes[1], sizes[2]);
        h * (d + 1) + h + 1 + q
    } else {
        sizes.last().copied().unwrap_or(1) * parameter_count(sizes)
    }
}

/// Multiply-adds per training sample of one Levenberg-Marquardt
/// iteration's Gauss-Newton products for a network of layer sizes `sizes`
/// (the lower triangles of the Gram matrices), by whichever computation
/// its fit takes: what a fit's time grows with from one network to
/// another.
///
/// ```
/// use twostage_fit::products_per_sample;
/// // One target: the Jacobian's row of 121 weights, 121^2 / 2.
/// assert_eq!(products_per_sample(&[4, 20, 1]), 7320.5);
/// // Seven targets share the hidden layer: 100^2 / 2 + 100 * 21 + 21^2 / 2,
/// // where the Jacobian's rows would take 7 * 247^2 / 2.
/// assert_eq!(products_per_sample(&[4, 20, 7]), 7320.5);
/// ```
pub fn products_per_sample(sizes: &[usize]) -> f64 {
    if by_structure(sizes) {
        let (d, h) = (sizes[0] as f64, sizes[1] as f64);
        let units = h * (d + 1.0);
        units * units / 2.0 + units * (h + 1.0) + (h + 1.0) * (h + 1.0) / 2.0
    } else {
        let weights = parameter_count(sizes) as f64;
        sizes.last().copied().unwrap_or(1) as f64 * weights * weights / 2.0
    }
}

/// Scratch and results of the structured products of one restart.
pub(super) struct HiddenLayerProducts {
    inputs: usize,
    hidden: usize,
    targets: usize,
    samples: usize,
    /// `s_n (x) [x_n; 1]` per sample (unit-major rows).
    ut: Vec<f64>,
    /// `[z_n; 1]` per sample.
    zt: Vec<f64>,
    /// Residuals, samples x targets row-major (targets x samples
    /// column-major).
    res: Vec<f64>,
    /// The weights `ut`, `zt` and `res` were computed at, if any.
    evaluated_at: Option<Vec<f64>>,
    unit_gram: Mat<f64>,
    cross: Mat<f64>,
    hidden_gram: Mat<f64>,
    back: Mat<f64>,
    unit_gradient: Mat<f64>,
    output_gradient: Mat<f64>,
}

impl HiddenLayerProducts {
    /// Scratch for `problem`, whose network has one hidden layer.
    pub(super) fn new(problem: &Problem<'_>) -> Self {
        let (d, h, q) = (problem.sizes[0], problem.sizes[1], problem.sizes[2]);
        let samples = problem.train.len();
        let units = h * (d + 1);
        Self {
            inputs: d,
            hidden: h,
            targets: q,
            samples,
            ut: vec![0.0; units * samples],
            zt: vec![0.0; (h + 1) * samples],
            res: vec![0.0; q * samples],
            evaluated_at: None,
            unit_gram: Mat::zeros(units, units),
            cross: Mat::zeros(units, h + 1),
            hidden_gram: Mat::zeros(h + 1, h + 1),
            back: Mat::zeros(h, samples),
            unit_gradient: Mat::zeros(units, 1),
            output_gradient: Mat::zeros(h + 1, q),
        }
    }

    /// The residuals at `params` into `r` (samples x targets, row-major),
    /// the products' terms there kept for [`Self::products`] at the same
    /// weights: Levenberg-Marquardt asks for the products where it last
    /// evaluated the residuals, the step it accepted.
    pub(super) fn evaluate(&mut self, problem: &Problem<'_>, params: &[f64], r: &mut [f64]) {
        self.compute_terms(problem, params);
        r.copy_from_slice(&self.res);
    }

    fn compute_terms(&mut self, problem: &Problem<'_>, params: &[f64]) {
        problem.hidden_layer_terms(params, &mut self.ut, &mut self.zt, &mut self.res);
        let at = self.evaluated_at.get_or_insert_with(Vec::new);
        at.clear();
        at.extend_from_slice(params);
    }

    /// The lower triangle of `scale J'J` (row-major, `n x n` for the
    /// network's `n` weights) and `scale J'r` at `params`.
    pub(super) fn products(
        &mut self,
        problem: &Problem<'_>,
        params: &[f64],
        scale: f64,
        jtj: &mut [f64],
        jtr: &mut [f64],
    ) {
        let (d, h, q, samples) = (self.inputs, self.hidden, self.targets, self.samples);
        let units = h * (d + 1);
        if !self
            .evaluated_at
            .as_deref()
            .is_some_and(|at| same_bits(at, params))
        {
            self.compute_terms(problem, params);
        }
        let ut = MatRef::from_column_major_slice(&self.ut, units, samples);
        let zt = MatRef::from_column_major_slice(&self.zt, h + 1, samples);
        let rt = MatRef::from_column_major_slice(&self.res, q, samples);
        // The output weights V (targets x hidden units, row-major).
        let v = MatRef::from_row_major_slice(&params[units..units + q * h], q, h);
        lower_gram(ut, scale, self.unit_gram.as_mut());
        tiled_product(ut, zt.transpose(), scale, self.cross.as_mut());
        matmul(
            self.hidden_gram.as_mut(),
            Accum::Replace,
            zt,
            zt.transpose(),
            scale,
            Par::Seq,
        );
        // Each sample's residuals sent back to the hidden units: V' r_n.
        matmul(
            self.back.as_mut(),
            Accum::Replace,
            v.transpose(),
            rt,
            1.0,
            Par::Seq,
        );
        for unit in 0..h {
            matmul(
                self.unit_gradient
                    .as_mut()
                    .subrows_mut(unit * (d + 1), d + 1),
                Accum::Replace,
                ut.subrows(unit * (d + 1), d + 1),
                self.back.as_ref().row(unit).transpose().as_mat(),
                scale,
                Par::Seq,
            );
        }
        matmul(
            self.output_gradient.as_mut(),
            Accum::Replace,
            zt,
            rt.transpose(),
            scale,
            Par::Seq,
        );
        self.assemble(v, params.len(), jtj, jtr);
    }

    /// Where the structured blocks go in the network's weight order: the
    /// first layer's weights unit by unit, then its biases; the output
    /// layer's likewise.
    fn assemble(&self, v: MatRef<'_, f64>, n: usize, jtj: &mut [f64], jtr: &mut [f64]) {
        let (d, h, q) = (self.inputs, self.hidden, self.targets);
        let units = h * (d + 1);
        let first = |a: usize| {
            let (unit, input) = (a / (d + 1), a % (d + 1));
            if input < d {
                unit * d + input
            } else {
                h * d + unit
            }
        };
        let output = |p: usize, k: usize| {
            if k < h {
                units + p * h + k
            } else {
                units + q * h + p
            }
        };
        let mut set = |i: usize, j: usize, value: f64| {
            let (row, column) = if i >= j { (i, j) } else { (j, i) };
            jtj[row * n + column] = value;
        };
        // The output weights' Gram matrix V'V weights the first layer's.
        let mut weights = Mat::<f64>::zeros(h, h);
        matmul(
            weights.as_mut(),
            Accum::Replace,
            v.transpose(),
            v,
            1.0,
            Par::Seq,
        );
        for a in 0..units {
            for b in 0..=a {
                let value = weights[(a / (d + 1), b / (d + 1))] * self.unit_gram[(a, b)];
                set(first(a), first(b), value);
            }
        }
        for p in 0..q {
            for k in 0..=h {
                for a in 0..units {
                    set(
                        output(p, k),
                        first(a),
                        v[(p, a / (d + 1))] * self.cross[(a, k)],
                    );
                }
                for other in 0..q {
                    for l in 0..=h {
                        let value = if other == p {
                            let (row, column) = if k >= l { (k, l) } else { (l, k) };
                            self.hidden_gram[(row, column)]
                        } else {
                            0.0
                        };
                        set(output(p, k), output(other, l), value);
                    }
                }
            }
        }
        for a in 0..units {
            jtr[first(a)] = self.unit_gradient[(a, 0)];
        }
        for p in 0..q {
            for k in 0..=h {
                jtr[output(p, k)] = self.output_gradient[(k, p)];
            }
        }
    }
}

/// Whether two weight vectors are the same bits: the products kept at
/// one point serve only that very point.
pub(super) fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[cfg(test)]
mod tests {
    use ndarray::Array2;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::mlp::network::initial_parameters;

    /// The tiled products against a plain triple loop, with a width that
    /// is not a multiple of the tile.
    #[test]
    fn gram_products_match_the_plain_sums() {
        // Tiles of 16, 48 and 96 columns, each size leaving a ragged last
        // tile.
        for n in [2 * GRAM_TILE + 5, 301, 600] {
            gram_products_match_the_plain_sums_at(n);
        }
        assert_eq!(
            (gram_tile(37), gram_tile(301), gram_tile(600)),
            (16, 48, 96)
        );
    }

    fn gram_products_match_the_plain_sums_at(n: usize) {
        let rows = 53;
        let value = |i: usize| ((i * 7919 + 13) % 101) as f64 / 50.0 - 1.0;
        let jt: Vec<f64> = (0..n * rows).map(value).collect();
        let res: Vec<f64> = (0..rows).map(|i| value(i + 5000)).collect();
        let (mut jtj, mut jtr) = (Mat::zeros(n, n), Mat::zeros(n, 1));
        gram_products(&jt, &res, 0.5, &mut jtj, &mut jtr);
        for i in 0..n {
            let mut gradient = 0.0;
            for r in 0..rows {
                gradient += jt[r * n + i] * res[r];
            }
            assert!((jtr[(i, 0)] - 0.5 * gradient).abs() < 1e-12, "J'r[{i}]");
            for j in 0..=i {
                let mut product = 0.0;
                for r in 0..rows {
                    product += jt[r * n + i] * jt[r * n + j];
                }
                assert!((jtj[(i, j)] - 0.5 * product).abs() < 1e-12, "J'J[{i}, {j}]");
            }
        }
    }

    /// The structured products against the Jacobian's, on a network whose
    /// rows span several blocks: the same numbers in another order.
    #[test]
    fn structured_products_match_the_jacobians() {
        let sizes = [3, 5, 4];
        let samples = 700;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let x = Array2::from_shape_fn((samples, 3), |_| rng.random_range(-2.0..2.0));
        let t = Array2::from_shape_fn((samples, 4), |_| rng.random_range(-1.0..1.0));
        let order: Vec<usize> = (0..samples).rev().collect();
        let (held_out, train) = order.split_at(100);
        let problem = Problem {
            sizes: &sizes,
            offsets: vec![0, 3, 8, 12],
            x: &x,
            t: &t,
            train,
            held_out,
            decay: 0.0,
            curvature_rows: None,
        };
        let params = initial_parameters(&sizes, &mut rng);
        let n = params.len();
        let rows = train.len() * 4;
        let (mut jt, mut res) = (vec![0.0; n * rows], vec![0.0; rows]);
        problem.jacobian(&params, &mut jt, &mut res, None);
        // The Jacobian from the activations its residuals kept: the same
        // bits as with its own forward passes.
        let mut kept = vec![0.0; train.len() * problem.activations_per_sample()];
        let mut kept_r = vec![0.0; rows];
        problem.residuals_keeping(&params, &mut kept_r, Some(&mut kept));
        let (mut jt_kept, mut res_kept) = (vec![0.0; n * rows], vec![0.0; rows]);
        problem.jacobian(&params, &mut jt_kept, &mut res_kept, Some(&kept));
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
        assert_eq!(bits(&jt_kept), bits(&jt));
        assert_eq!(bits(&res_kept), bits(&res));
        assert_eq!(bits(&kept_r), bits(&res));
        let (mut jtj, mut jtr) = (Mat::zeros(n, n), Mat::zeros(n, 1));
        gram_products(&jt, &res, 0.25, &mut jtj, &mut jtr);
        let mut structured = HiddenLayerProducts::new(&problem);
        let (mut sjtj, mut sjtr) = (vec![f64::NAN; n * n], vec![f64::NAN; n]);
        structured.products(&problem, &params, 0.25, &mut sjtj, &mut sjtr);
        let largest = (0..n)
            .flat_map(|i| (0..=i).map(move |j| (i, j)))
            .map(|(i, j)| jtj[(i, j)].abs())
            .fold(0.0, f64::max);
        for i in 0..n {
            let gradient = jtr[(i, 0)];
            assert!((sjtr[i] - gradient).abs() <= 1e-12 * largest, "J'r[{i}]");
            for j in 0..=i {
                let (a, b) = (sjtj[i * n + j], jtj[(i, j)]);
                assert!(
                    (a - b).abs() <= 1e-12 * largest,
                    "J'J[{i}, {j}]: {a} against {b}"
                );
            }
        }
        // Residuals evaluated elsewhere in between, or at these weights:
        // the same products to the bit, and the Jacobian's residuals.
        let elsewhere: Vec<f64> = params.iter().map(|p| p * 0.9).collect();
        let mut r = vec![0.0; rows];
        for at in [&elsewhere, &params] {
            structured.evaluate(&problem, at, &mut r);
            let (mut again, mut again_r) = (vec![f64::NAN; n * n], vec![f64::NAN; n]);
            structured.products(&problem, &params, 0.25, &mut again, &mut again_r);
            assert_eq!(bits(&again), bits(&sjtj));
            assert_eq!(bits(&again_r), bits(&sjtr));
        }
        assert_eq!(bits(&r), bits(&res));
        assert!(by_structure(&sizes));
        assert!(!by_structure(&[3, 5, 1]));
        assert!(!by_structure(&[3, 5, 5, 4]));
    }
}
