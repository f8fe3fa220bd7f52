//! How much a least-squares fit improves on an estimate by the model's
//! noise alone. A record the model makes at `theta`, fitted again, lowers
//! its output-error loss by the share of its noise that lies in the span
//! of the model's response to small parameter changes: to first order,
//! `|P r|^2` with `P` the projection onto the span of the residuals'
//! Jacobian at `theta` (the likelihood-ratio statistic of nonlinear least
//! squares: Bates and Watts, Nonlinear Regression Analysis and Its
//! Applications, 1988, ch. 2). The check ranks a record's own
//! improvement, its best fit's loss below the estimate's, among those of
//! the model's noisy records at the estimate: an estimate the best fit
//! beats by more than the noise would have been beaten is not the model's
//! explanation of the record, however typical its misfit.

use twostage_fit::CentralDifferences;
use twostage_kernels::cholesky::{PivotRule, cholesky_in_place, solve_lower_in_place};
use twostage_models::{IoData, Simulator};

use crate::RefineError;
use crate::lockstep::{to_theta, to_unit};
use crate::output_error::OutputError;
use crate::refinement::ResidualModel;

/// The span of the model's response near an estimate, over a scoring
/// window of a record: the output errors' Jacobian (central differences in
/// the prior's unit box, the columns that move the record) and the
/// Cholesky factor `L` of its Gram matrix, so that the first-order
/// improvement of residuals `r` is `|L^-1 J' r|^2`.
#[derive(Debug, Clone)]
pub(crate) struct ResponseSpan {
    /// The window's rows of each kept column, one column after another.
    columns: Vec<f64>,
    /// The residuals' rows the window keeps, in each output.
    rows: Vec<std::ops::Range<usize>>,
    /// How many columns were kept.
    rank: usize,
    /// `L`, row-major `rank x rank`.
    factor: Vec<f64>,
}

impl ResponseSpan {
    /// The span at `theta` on `record`'s input through `sim`'s output
    /// errors ([`OutputError`]: each output scaled by the record's own
    /// spread), over the samples of `window` of every output, the
    /// differences kept inside the prior's box where `theta` is. A
    /// parameter that does not move those samples (its column within
    /// `1e-6` of the others' span) is left out: no fit gains by it.
    ///
    /// # Errors
    /// A source that cannot run without noise on a given input, a run that
    /// fails.
    pub(crate) fn at(
        sim: &dyn Simulator,
        record: &IoData,
        theta: &[f64],
        window: std::ops::Range<usize>,
    ) -> Result<Self, RefineError> {
        let loss = OutputError::new(sim)?;
        let prior = sim.spec().prior();
        let q = prior.dim();
        let (zeros, ones) = (vec![0.0; q], vec![1.0; q]);
        let unit = to_unit(prior, theta);
        // Inside the prior's box the points stay in it; values checked
        // outside it (given, not estimated) are differenced where they are.
        let inside = unit.iter().all(|u| (0.0..=1.0).contains(u));
        let (differences, points) =
            CentralDifferences::at(&unit, inside.then_some((&zeros[..], &ones[..])));
        let thetas: Vec<Vec<f64>> = points.iter().map(|p| to_theta(prior, p)).collect();
        let pairs: Vec<(&[f64], &IoData)> = thetas.iter().map(|t| (t.as_slice(), record)).collect();
        let mut values = vec![Vec::new(); pairs.len()];
        for result in loss.residuals_batch(&pairs, &mut values) {
            result?;
        }
        let n = record.n_samples();
        let total = loss.n_residuals(record);
        let jacobian = differences.jacobian(&values, total);
        let rows: Vec<_> = (0..total / n.max(1))
            .map(|j| j * n + window.start.min(n)..j * n + window.end.min(n))
            .collect();
        let windowed: Vec<Vec<f64>> = (0..q)
            .map(|a| {
                let column = &jacobian[a * total..(a + 1) * total];
                rows.iter()
                    .flat_map(|r| column[r.clone()].iter().copied())
                    .collect()
            })
            .collect();
        Ok(Self::of_columns(windowed, rows))
    }

    /// The span of `columns` (each as long as `rows` keep), dropping each
    /// column within `1e-6` of the span of those kept before it.
    fn of_columns(mut columns: Vec<Vec<f64>>, rows: Vec<std::ops::Range<usize>>) -> Self {
        loop {
            let k = columns.len();
            let mut factor = vec![0.0; k * k];
            for a in 0..k {
                for b in 0..=a {
                    factor[a * k + b] = dot(&columns[a], &columns[b]);
                }
            }
            match cholesky_in_place(&mut factor, k, PivotRule::Angle(1e-6)) {
                Ok(()) => {
                    return Self {
                        columns: columns.concat(),
                        rows,
                        rank: k,
                        factor,
                    };
                }
                Err(refused) => {
                    columns.remove(refused.column);
                }
            }
        }
    }

    /// The first-order improvement a least-squares fit makes on
    /// `residuals` (laid out as the record's output errors, every sample of
    /// every output): `|L^-1 J' r|^2` over the window's rows.
    pub(crate) fn improvement(&self, residuals: &[f64]) -> f64 {
        let kept: Vec<f64> = self
            .rows
            .iter()
            .flat_map(|r| residuals[r.clone()].iter().copied())
            .collect();
        let mut z: Vec<f64> = self
            .columns
            .chunks_exact(kept.len().max(1))
            .take(self.rank)
            .map(|column| dot(column, &kept))
            .collect();
        solve_lower_in_place(&self.factor[..], self.rank, &mut z);
        z.iter().map(|v| v * v).sum()
    }

    /// The loss over the window's rows of `residuals` (laid out as
    /// [`Self::improvement`]'s).
    pub(crate) fn window_loss(&self, residuals: &[f64]) -> f64 {
        self.rows
            .iter()
            .flat_map(|r| residuals[r.clone()].iter())
            .map(|v| v * v)
            .sum()
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One column `u`: the improvement of `r` is the least-squares fit's,
    /// `(u'r)^2 / u'u`, by hand.
    #[test]
    fn one_column_improves_by_the_hand_computed_amount() {
        let u = vec![1.0, -2.0, 0.5, 3.0];
        let r = [0.3, 0.1, -0.7, 0.2];
        let span = ResponseSpan::of_columns(vec![u.clone()], std::iter::once(0..4).collect());
        let expected = dot(&u, &r).powi(2) / dot(&u, &u);
        assert!((span.improvement(&r) - expected).abs() < 1e-15);
        assert!((span.window_loss(&r) - dot(&r, &r)).abs() < 1e-15);
    }

    /// Two columns: the improvement is the loss of `r` less the loss of its
    /// least-squares residual, solved here by the normal equations' closed
    /// form (Cramer's rule); a third column in their span changes nothing.
    #[test]
    fn two_columns_improve_by_the_fitted_share_and_a_repeated_one_is_left_out() {
        let a = vec![1.0, 0.0, 2.0, -1.0, 0.5];
        let b = vec![0.0, 1.0, 1.0, 3.0, -2.0];
        let r = [0.4, -0.3, 0.9, 0.1, -0.6];
        let (aa, ab, bb) = (dot(&a, &a), dot(&a, &b), dot(&b, &b));
        let (ar, br) = (dot(&a, &r), dot(&b, &r));
        let det = aa * bb - ab * ab;
        let (x, y) = ((bb * ar - ab * br) / det, (aa * br - ab * ar) / det);
        let fitted: f64 = (0..5).map(|k| (r[k] - x * a[k] - y * b[k]).powi(2)).sum();
        let expected = dot(&r, &r) - fitted;
        let span =
            ResponseSpan::of_columns(vec![a.clone(), b.clone()], std::iter::once(0..5).collect());
        assert!((span.improvement(&r) - expected).abs() < 1e-12);
        let sum: Vec<f64> = a.iter().zip(&b).map(|(p, q)| 2.0 * p - q).collect();
        let repeated = ResponseSpan::of_columns(vec![a, sum, b], std::iter::once(0..5).collect());
        assert_eq!(repeated.rank, 2);
        assert!((repeated.improvement(&r) - expected).abs() < 1e-12);
    }

    /// A window keeps each output's samples from its start: the residuals
    /// before it are not read.
    #[test]
    fn a_window_reads_only_its_rows() {
        // Two outputs of three samples, the window from sample 1.
        let rows = vec![1..3, 4..6];
        let u = vec![1.0, 2.0, -1.0, 1.0];
        let span = ResponseSpan::of_columns(vec![u.clone()], rows);
        let r = [100.0, 0.5, 0.25, -100.0, 1.0, 0.0];
        let kept = [0.5, 0.25, 1.0, 0.0];
        let expected = dot(&u, &kept).powi(2) / dot(&u, &u);
        assert!((span.improvement(&r) - expected).abs() < 1e-15);
        assert!((span.window_loss(&r) - dot(&kept, &kept)).abs() < 1e-15);
    }
}
