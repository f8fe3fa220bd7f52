//! The uncertainty of a least-squares estimate from its record alone: the
//! local curvature of the loss (the Jacobian of the residuals) with the
//! residuals' own variance and autocorrelation, as the sandwich
//! `(J'J)^-1 J' Gamma J (J'J)^-1` of least squares under stationary
//! coloured noise (Ljung, System Identification, 2nd ed., 1999, sec. 9.3),
//! `Gamma` the autocovariances of an autoregressive model of the residuals
//! (Yule-Walker, the order by BIC). Output errors of a model with process
//! noise, or of one that misses part of the plant, are correlated in time:
//! the classic `s^2 (J'J)^-1` would then be several times too narrow.
//!
//! Not a kernel (HAC) estimate of the scores' long-run variance: a
//! parameter that only a few samples determine (an initial state, seen in
//! the first samples' transient) has scores on those samples alone, whose
//! fitted residuals are near zero; the kernel estimate was then many times
//! too narrow. The noise model is estimated from all the
//! samples, whatever the parameter.

use twostage_fit::CentralDifferences;
use twostage_kernels::cholesky::{PivotRule, cholesky_in_place, solve_cholesky_in_place};
use twostage_models::{ArNoise, IoData, truncated_standard_mean};

use crate::error::RefineError as Error;
use crate::lockstep::{to_theta, to_unit};
use crate::refinement::{Refinement, ResidualModel};

/// An estimate's uncertainty (or why it has none: the record does not
/// determine some parameter) with its residuals.
pub(crate) type WithResiduals = (Result<LocalUncertainty, Error>, Vec<f64>);

/// The local uncertainty of an estimate: see [`Refinement::uncertainty`].
#[derive(Debug, Clone, PartialEq)]
pub struct LocalUncertainty {
    /// Per parameter, the standard deviation of the estimate.
    pub sd: Vec<f64>,
    /// The correlation matrix of the parameters (row-major q x q).
    pub correlation: Vec<f64>,
    /// The order of the autoregressive model of the residuals (0: white;
    /// of several outputs, the largest).
    pub noise_order: usize,
}

impl LocalUncertainty {
    /// Half-widths of the two-sided intervals of level `1 - alpha` under a
    /// normal approximation, `z_{1 - alpha/2} sd`.
    pub fn half_widths(&self, alpha: f64) -> Vec<f64> {
        let z = twostage_models::standard_normal_quantile(1.0 - alpha / 2.0);
        self.sd.iter().map(|s| z * s).collect()
    }

    /// The mean near the best fit `best` of the likelihood's normal
    /// approximation there (these standard deviations) within the box
    /// `[lower, upper]`, parameter by parameter: the posterior mean under a
    /// flat prior on the box. A parameter the record leaves loose near a
    /// bound is pulled inside, where the likelihood's mass in the box
    /// lies; one the record pins down keeps its best fit. The box's bounds
    /// are weighed, not a prior's density (a prior drawn to spread a chart
    /// is not a belief a real record should be pulled towards), and the
    /// correlations are left out. Parameters without a finite positive
    /// standard deviation keep their best fit.
    ///
    /// ```
    /// use twostage_refine::LocalUncertainty;
    /// let local = LocalUncertainty { sd: vec![0.5, 0.01], correlation: vec![1.0, 0.0, 0.0, 1.0], noise_order: 0 };
    /// // A best fit on the lower bound of a loose parameter: the mean of a
    /// // half-normal above it, sd sqrt(2 / pi) further in; the pinned
    /// // parameter, far from its bounds, stays where it is.
    /// let mean = local.mean_within_box(&[0.0, 5.0], &[0.0, 0.0], &[100.0, 10.0]);
    /// let half_normal = 0.5 * (2.0 / std::f64::consts::PI).sqrt();
    /// assert!((mean[0] - half_normal).abs() < 1e-12 && (mean[1] - 5.0).abs() < 1e-12);
    /// ```
    pub fn mean_within_box(&self, best: &[f64], lower: &[f64], upper: &[f64]) -> Vec<f64> {
        best.iter()
            .zip(&self.sd)
            .zip(lower.iter().zip(upper))
            .map(|((&at, &sd), (&low, &high))| {
                truncated_normal_mean(at, sd, low, high).unwrap_or(at)
            })
            .collect()
    }

    /// The uncertainty of the parameters at `places` alone, in that order
    /// (a record's parameters among a joint fit's).
    pub(crate) fn of(&self, places: &[usize]) -> Self {
        let q = self.sd.len();
        Self {
            sd: places.iter().map(|&a| self.sd[a]).collect(),
            correlation: places
                .iter()
                .flat_map(|&a| places.iter().map(move |&b| self.correlation[a * q + b]))
                .collect(),
            noise_order: self.noise_order,
        }
    }

    /// The same with NaN at the parameters marked in `unknown` (their sd
    /// and their correlations with any other).
    pub(crate) fn without(&self, unknown: &[bool]) -> Self {
        let q = self.sd.len();
        Self {
            sd: (0..q)
                .map(|a| if unknown[a] { f64::NAN } else { self.sd[a] })
                .collect(),
            correlation: (0..q * q)
                .map(|k| {
                    if unknown[k / q] || unknown[k % q] {
                        f64::NAN
                    } else {
                        self.correlation[k]
                    }
                })
                .collect(),
            noise_order: self.noise_order,
        }
    }
}

impl<M: ResidualModel> Refinement<M> {
    /// The covariance of the least-squares estimate `theta` of `record`
    /// from the record alone: `A^-1 B A^-1` with `A = J'J` (central
    /// differences, the `2q` points asked for in one batch with `theta`
    /// itself) and `B = J' Gamma J`, `Gamma` the autocovariances of an
    /// autoregressive model of the residuals (order by BIC, at most 20,
    /// variance scaled by `T / (T - q)`). Residuals of several outputs (the
    /// model's `n_residuals` a multiple of the record's samples) each get
    /// their own noise model. Meant for the minimum
    /// of the loss (a refined estimate): elsewhere the gradient is not
    /// zero and the sandwich does not apply.
    ///
    /// ```
    /// use twostage_models::{IoData, Prior};
    /// use twostage_refine::{RefineError, Refinement, ResidualModel};
    /// # struct ConstantMean(Prior);
    /// # impl ResidualModel for ConstantMean {
    /// #     type Error = RefineError;
    /// #     fn prior(&self) -> &Prior { &self.0 }
    /// #     fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
    /// #         for (r, y) in r.iter_mut().zip(record.output(0)) { *r = y - theta[0]; }
    /// #         Ok(())
    /// #     }
    /// # }
    /// // y_k = theta + e_k, at the sample mean 0 of residuals that are not
    /// // correlated from one sample to the next: the textbook standard
    /// // error of a mean, sqrt(sum r^2 / (n - 1) / n) = sqrt(2 / 3) / 2.
    /// let fit = Refinement::new(ConstantMean(Prior::uniform_box(&[-5.0], &[5.0])?));
    /// let record = IoData::siso(&[0.0; 4], &[1.0, 0.0, -1.0, 0.0])?;
    /// let local = fit.uncertainty(&record, &[0.0])?;
    /// assert_eq!(local.noise_order, 0);
    /// assert!((local.sd[0] - (2.0f64 / 3.0).sqrt() / 2.0).abs() < 1e-6, "{local:?}");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// A `theta` of the wrong length, an evaluation that fails, residuals
    /// that do not vary with some parameter (the record does not
    /// determine it).
    pub fn uncertainty(
        &self,
        record: &IoData,
        theta: &[f64],
    ) -> Result<LocalUncertainty, M::Error> {
        self.uncertainties(&[(record, theta)])
            .pop()
            .unwrap_or_else(|| unreachable!("one result per estimate"))
    }

    /// [`Refinement::uncertainty`] of many estimates, each of its own
    /// record, their `2q + 1` points each asked for in one batch (as the
    /// descents of [`Refinement::descents_of_records`] are): one result per
    /// estimate, in order.
    pub fn uncertainties(
        &self,
        estimates: &[(&IoData, &[f64])],
    ) -> Vec<Result<LocalUncertainty, M::Error>> {
        self.uncertainties_and_residuals(estimates)
            .into_iter()
            .map(|found| found.and_then(|(local, _)| local.map_err(M::Error::from)))
            .collect()
    }

    /// [`Refinement::uncertainties`], each with the residuals at its
    /// estimate (computed on the way, and kept where the interval fails).
    pub(crate) fn uncertainties_and_residuals(
        &self,
        estimates: &[(&IoData, &[f64])],
    ) -> Vec<Result<WithResiduals, M::Error>> {
        let span = self.span();
        self.linearizations(estimates)
            .into_iter()
            .map(|found| {
                found.map(|at| {
                    let local = at.covariance().map(|(covariance, noise_order)| {
                        local_uncertainty(&covariance, &span, noise_order)
                    });
                    (local, at.residuals)
                })
            })
            .collect()
    }

    /// The prior box's widths: a unit coordinate's length in the
    /// parameters' own.
    pub(crate) fn span(&self) -> Vec<f64> {
        let prior = self.model().prior();
        (0..prior.dim())
            .map(|j| prior.upper()[j] - prior.lower()[j])
            .collect()
    }

    /// Each estimate's residuals and their Jacobian in unit coordinates
    /// (central differences), the `2q + 1` points of every estimate asked
    /// for in one batch.
    pub(crate) fn linearizations(
        &self,
        estimates: &[(&IoData, &[f64])],
    ) -> Vec<Result<Linearized, M::Error>> {
        let model = self.model();
        let prior = model.prior();
        let q = prior.dim();
        let (zeros, ones) = (vec![0.0; q], vec![1.0; q]);
        // Each estimate's differences, or why it has none.
        let mut prepared = Vec::with_capacity(estimates.len());
        let mut thetas: Vec<Vec<f64>> = Vec::new();
        let mut records: Vec<&IoData> = Vec::new();
        for (record, theta) in estimates {
            if theta.len() != q {
                prepared.push(Err(Error::Length {
                    what: "the estimate",
                    found: theta.len(),
                    expected: q,
                }));
                continue;
            }
            let unit = to_unit(prior, theta);
            let (differences, points) = CentralDifferences::at(&unit, Some((&zeros, &ones)));
            let first = thetas.len();
            thetas.push(theta.to_vec());
            thetas.extend(points.iter().map(|p| to_theta(prior, p)));
            records.resize(thetas.len(), record);
            prepared.push(Ok((differences, first)));
        }
        let pairs: Vec<(&[f64], &IoData)> = thetas
            .iter()
            .map(Vec::as_slice)
            .zip(records.iter().copied())
            .collect();
        let mut values = vec![Vec::new(); thetas.len()];
        let mut results: Vec<Option<M::Error>> = model
            .residuals_batch(&pairs, &mut values)
            .into_iter()
            .map(Result::err)
            .collect();
        prepared
            .into_iter()
            .zip(estimates)
            .map(|(prepared, (record, _))| {
                let (differences, first) = prepared.map_err(M::Error::from)?;
                let count = 2 * q + 1;
                if let Some(e) = results[first..first + count]
                    .iter_mut()
                    .find_map(Option::take)
                {
                    return Err(e);
                }
                let mut mine: Vec<Vec<f64>> = values[first..first + count]
                    .iter_mut()
                    .map(std::mem::take)
                    .collect();
                let residuals = mine.remove(0);
                let n = residuals.len();
                let columns = differences.jacobian(&mine, n);
                let mut runs = model.residual_runs(record);
                if runs.iter().sum::<usize>() != n {
                    runs = vec![n];
                }
                Ok(Linearized {
                    columns,
                    residuals,
                    runs,
                    q,
                })
            })
            .collect()
    }
}

/// An estimate's residuals and their Jacobian in the prior box's unit
/// coordinates: what its interval, and a record's own step from it, are
/// made of.
pub(crate) struct Linearized {
    /// The Jacobian, column by column (each `residuals.len()` long).
    columns: Vec<f64>,
    /// The residuals at the estimate.
    pub(crate) residuals: Vec<f64>,
    /// The lengths of the residuals' runs (an output of a record each).
    runs: Vec<usize>,
    /// The parameters.
    q: usize,
}

impl Linearized {
    /// `A^-1 B A^-1` of the whole, and the largest autoregressive order
    /// taken ([`sandwich`]).
    pub(crate) fn covariance(&self) -> Result<(Vec<f64>, usize), Error> {
        sandwich(&self.columns, &self.residuals, self.q, &self.runs)
    }

    /// The same residuals with the Jacobian's columns `keep` alone, in
    /// that order: a loss of some of the parameters, the others held.
    pub(crate) fn columns_of(&self, keep: &[usize]) -> Self {
        let n = self.residuals.len();
        Self {
            columns: keep
                .iter()
                .flat_map(|&a| self.columns[a * n..(a + 1) * n].iter().copied())
                .collect(),
            residuals: self.residuals.clone(),
            runs: self.runs.clone(),
            q: keep.len(),
        }
    }

    /// The residuals `from..from + n` (whole runs) and their rows of the
    /// Jacobian, the runs `runs`: one record of several fitted together.
    pub(crate) fn part(&self, from: usize, n: usize, runs: Vec<usize>) -> Self {
        let whole = self.residuals.len();
        let columns = (0..self.q)
            .flat_map(|a| {
                self.columns[a * whole + from..a * whole + from + n]
                    .iter()
                    .copied()
            })
            .collect();
        Self {
            columns,
            residuals: self.residuals[from..from + n].to_vec(),
            runs,
            q: self.q,
        }
    }

    /// The Gauss-Newton step `-A^-1 J' r` of this loss alone from where it
    /// was linearized (unit coordinates), where its own best fit lies to
    /// first order, with that best fit's covariance (the sandwich of the
    /// residuals there, `r + J step`).
    ///
    /// # Errors
    /// Residuals that do not change with some parameter.
    pub(crate) fn own_step(&self) -> Result<(Vec<f64>, Vec<f64>), Error> {
        let (q, n) = (self.q, self.residuals.len());
        let mut factor = bread(&self.columns, n, q);
        cholesky_in_place(&mut factor, q, PivotRule::RelativeToLargest(1e-12))
            .map_err(|_| undetermined())?;
        let mut step: Vec<f64> = (0..q)
            .map(|a| {
                -self.columns[a * n..(a + 1) * n]
                    .iter()
                    .zip(&self.residuals)
                    .map(|(j, r)| j * r)
                    .sum::<f64>()
            })
            .collect();
        solve_cholesky_in_place(&factor, q, &mut step);
        // The noise is judged on the residuals at the own best fit, `r +
        // J step`: at the joint estimate they hold the very offset whose
        // size is in question.
        let mut residuals = self.residuals.clone();
        for (a, s) in step.iter().enumerate() {
            for (r, j) in residuals.iter_mut().zip(&self.columns[a * n..(a + 1) * n]) {
                *r += j * s;
            }
        }
        let (covariance, _) = sandwich(&self.columns, &residuals, q, &self.runs)?;
        Ok((step, covariance))
    }
}

/// The error of residuals that some parameter does not move.
fn undetermined() -> Error {
    Error::Numerical {
        what: "the residuals do not change with some parameter near the estimate: the record \
               does not determine it, and it has no interval"
            .into(),
    }
}

/// `J'J` (row-major q x q) of the Jacobian `columns`, each `n` long.
fn bread(columns: &[f64], n: usize, q: usize) -> Vec<f64> {
    let mut bread = vec![0.0; q * q];
    for a in 0..q {
        for b in 0..q {
            bread[a * q + b] = columns[a * n..(a + 1) * n]
                .iter()
                .zip(&columns[b * n..(b + 1) * n])
                .map(|(x, y)| x * y)
                .sum();
        }
    }
    bread
}

/// The sds and correlations of a covariance in unit coordinates, back in
/// the parameters' own (`span` the prior box's widths).
pub(crate) fn local_uncertainty(
    covariance: &[f64],
    span: &[f64],
    noise_order: usize,
) -> LocalUncertainty {
    let q = span.len();
    let sd_unit: Vec<f64> = (0..q)
        .map(|j| covariance[j * q + j].max(0.0).sqrt())
        .collect();
    let sd = sd_unit.iter().zip(span).map(|(s, w)| s * w).collect();
    let correlation = (0..q * q)
        .map(|k| {
            let (a, b) = (k / q, k % q);
            let scale = sd_unit[a] * sd_unit[b];
            if scale > 0.0 {
                covariance[k] / scale
            } else {
                f64::from(u8::from(a == b))
            }
        })
        .collect();
    LocalUncertainty {
        sd,
        correlation,
        noise_order,
    }
}

/// `A^-1 B A^-1` (row-major q x q) for the Jacobian `columns` (each `n`
/// long) and residuals `r`, made of consecutive runs of the lengths
/// `runs`, each a sequence in time; and the largest autoregressive order
/// taken.
fn sandwich(
    columns: &[f64],
    r: &[f64],
    q: usize,
    runs: &[usize],
) -> Result<(Vec<f64>, usize), Error> {
    let n = r.len();
    let mut meat = vec![0.0; q * q];
    let mut largest_order = 0;
    // Each run's residuals (an output of a record) are their own
    // stationary process; the runs' cross-correlation is not modelled.
    let mut offset = 0;
    for &length in runs {
        let residuals = &r[offset..offset + length];
        // Order by BIC up to 20: the same model a model file's coloured
        // noise is made of.
        let noise = ArNoise::fit(residuals, 20, q);
        largest_order = largest_order.max(noise.order());
        let jacobian = |a: usize| &columns[a * n + offset..a * n + offset + residuals.len()];
        // B = J' Gamma J with Gamma Toeplitz in the autocovariances.
        for (lag, gamma) in noise.autocovariances(residuals.len()).iter().enumerate() {
            for a in 0..q {
                for b in 0..q {
                    let (ja, jb) = (jacobian(a), jacobian(b));
                    let products: f64 = if lag == 0 {
                        ja.iter().zip(jb).map(|(x, y)| x * y).sum()
                    } else {
                        ja[lag..].iter().zip(jb).map(|(x, y)| x * y).sum::<f64>()
                            + jb[lag..].iter().zip(ja).map(|(x, y)| x * y).sum::<f64>()
                    };
                    meat[a * q + b] += gamma * products;
                }
            }
        }
        offset += length;
    }
    let mut factor = bread(columns, n, q);
    cholesky_in_place(&mut factor, q, PivotRule::RelativeToLargest(1e-12))
        .map_err(|_| undetermined())?;
    // A^-1 B, column by column of B (symmetric), then (A^-1 B) A^-1 likewise.
    let mut half = meat;
    for a in 0..q {
        let mut column: Vec<f64> = (0..q).map(|b| half[b * q + a]).collect();
        solve_cholesky_in_place(&factor, q, &mut column);
        for b in 0..q {
            half[b * q + a] = column[b];
        }
    }
    let mut covariance = vec![0.0; q * q];
    for a in 0..q {
        // Row a of (A^-1 B) A^-1 = A^-1 (row a of A^-1 B)' since A is symmetric.
        let mut row: Vec<f64> = half[a * q..(a + 1) * q].to_vec();
        solve_cholesky_in_place(&factor, q, &mut row);
        covariance[a * q..(a + 1) * q].copy_from_slice(&row);
    }
    Ok((covariance, largest_order))
}

/// The mean of `N(at, sd^2)` truncated to `[low, high]`; `None` without a
/// width or an interval the normal puts mass in.
fn truncated_normal_mean(at: f64, sd: f64, low: f64, high: f64) -> Option<f64> {
    if !(sd.is_finite() && sd > 0.0 && at.is_finite() && low < high) {
        return None;
    }
    let shift = truncated_standard_mean((low - at) / sd, (high - at) / sd)?;
    Some((at + sd * shift).clamp(low, high))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn local(sd: &[f64]) -> LocalUncertainty {
        let q = sd.len();
        LocalUncertainty {
            sd: sd.to_vec(),
            correlation: (0..q * q)
                .map(|i| if i % (q + 1) == 0 { 1.0 } else { 0.0 })
                .collect(),
            noise_order: 0,
        }
    }

    /// The mean of N(at, sd^2) on [low, high] by the midpoint rule on a
    /// fine grid: a second computation beside the closed form.
    fn mean_by_quadrature(at: f64, sd: f64, low: f64, high: f64) -> f64 {
        let cells = 200_000;
        let width = (high - low) / cells as f64;
        let (mut mass, mut first) = (0.0, 0.0);
        for i in 0..cells {
            let x = low + (i as f64 + 0.5) * width;
            let w = (-0.5 * ((x - at) / sd).powi(2)).exp();
            mass += w;
            first += w * x;
        }
        first / mass
    }

    #[test]
    fn the_mean_within_the_box_is_the_truncated_normal_one() {
        let (lower, upper) = ([-1.22, -42.8], [-0.98, -27.3]);
        for (at, sd) in [
            ([-0.99, -30.0], [0.05, 0.7]),
            ([-0.98, -27.5], [0.3, 2.0]),
            ([-1.1, -42.8], [0.01, 5.0]),
        ] {
            let mean = local(&sd).mean_within_box(&at, &lower, &upper);
            for j in 0..2 {
                let by_quadrature = mean_by_quadrature(at[j], sd[j], lower[j], upper[j]);
                assert!(
                    (mean[j] - by_quadrature).abs() < 1e-6 * sd[j],
                    "{at:?} {sd:?}: {} against {by_quadrature}",
                    mean[j]
                );
                assert!(lower[j] <= mean[j] && mean[j] <= upper[j]);
            }
        }
    }

    #[test]
    fn a_parameter_far_from_its_bounds_or_without_a_width_keeps_its_best_fit() {
        let mean = local(&[0.01, 0.0, f64::NAN]).mean_within_box(
            &[0.5, 0.0, 1.0],
            &[0.0, 0.0, 0.0],
            &[1.0, 1.0, 1.0],
        );
        let bits: Vec<u64> = mean.iter().map(|v| v.to_bits()).collect();
        assert_eq!(bits, [0.5f64.to_bits(), 0.0f64.to_bits(), 1.0f64.to_bits()]);
    }
}
