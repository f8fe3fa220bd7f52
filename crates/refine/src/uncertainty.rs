//! The uncertainty of a least-squares estimate from its record alone: the
//! local curvature of the loss (the Jacobian of the residuals) with the
//! residuals' own variance and autocorrelation, as a heteroskedasticity-
//! and autocorrelation-consistent (HAC) sandwich: the Bartlett kernel
//! (Newey and West, 1987, Econometrica 55(3)) on AR(1)-prewhitened scores
//! (Andrews and Monahan, 1992, Econometrica 60(4)), the bandwidth by
//! Andrews' AR(1) plug-in rule (1991, Econometrica 59(3), sec. 6, with the
//! Bartlett constant 1.1447). Output
//! errors of a model with process noise, or of one that misses part of the
//! plant, are correlated in time: the classic `s^2 (J'J)^-1` would then be
//! several times too narrow.

use twostage_fit::CentralDifferences;
use twostage_kernels::cholesky::{PivotRule, cholesky_in_place, solve_cholesky_in_place};
use twostage_models::IoData;

use crate::error::RefineError as Error;
use crate::lockstep::{to_theta, to_unit};
use crate::refinement::{Refinement, ResidualModel};

/// The local uncertainty of an estimate: see [`Refinement::uncertainty`].
#[derive(Debug, Clone, PartialEq)]
pub struct LocalUncertainty {
    /// Per parameter, the standard deviation of the estimate.
    pub sd: Vec<f64>,
    /// The correlation matrix of the parameters (row-major q x q).
    pub correlation: Vec<f64>,
    /// The lags of the residuals' autocorrelation taken in (0: white).
    pub bandwidth: usize,
}

impl LocalUncertainty {
    /// Half-widths of the two-sided intervals of level `1 - alpha` under a
    /// normal approximation, `z_{1 - alpha/2} sd`.
    pub fn half_widths(&self, alpha: f64) -> Vec<f64> {
        let z = twostage_models::standard_normal_quantile(1.0 - alpha / 2.0);
        self.sd.iter().map(|s| z * s).collect()
    }
}

impl<M: ResidualModel> Refinement<M> {
    /// The covariance of the least-squares estimate `theta` of `record`
    /// from the record alone: `A^-1 B A^-1` with `A = J'J` (central
    /// differences, the `2q` points asked for in one batch with `theta`
    /// itself) and `B` the Bartlett-weighted sum of the autocovariances of
    /// the scores `J_t' r_t` up to a bandwidth chosen from their lag-one
    /// autocorrelation. Residuals of several outputs (the model's
    /// `n_residuals` a multiple of the record's samples) are summed per
    /// sample before their autocovariances are taken. Meant for the minimum
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
    /// assert_eq!(local.bandwidth, 0);
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
        let model = self.model();
        let prior = model.prior();
        let q = prior.dim();
        if theta.len() != q {
            return Err(Error::Length {
                what: "the estimate",
                found: theta.len(),
                expected: q,
            }
            .into());
        }
        let unit = to_unit(prior, theta);
        let (zeros, ones) = (vec![0.0; q], vec![1.0; q]);
        let (differences, points) = CentralDifferences::at(&unit, Some((&zeros, &ones)));
        let thetas: Vec<Vec<f64>> = std::iter::once(theta.to_vec())
            .chain(points.iter().map(|p| to_theta(prior, p)))
            .collect();
        let pairs: Vec<(&[f64], &IoData)> = thetas.iter().map(|t| (t.as_slice(), record)).collect();
        let mut values = vec![Vec::new(); thetas.len()];
        for result in model.residuals_batch(&pairs, &mut values) {
            result?;
        }
        let residuals = values.remove(0);
        let n = residuals.len();
        let columns = differences.jacobian(&values, n);
        let samples = record.n_samples().max(1);
        let length = if n % samples == 0 { samples } else { n };
        let (covariance, bandwidth) = sandwich(&columns, &residuals, q, length)?;
        // Back from unit coordinates to the parameters' own.
        let span: Vec<f64> = (0..q)
            .map(|j| prior.upper()[j] - prior.lower()[j])
            .collect();
        let sd_unit: Vec<f64> = (0..q)
            .map(|j| covariance[j * q + j].max(0.0).sqrt())
            .collect();
        let sd = sd_unit.iter().zip(&span).map(|(s, w)| s * w).collect();
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
        Ok(LocalUncertainty {
            sd,
            correlation,
            bandwidth,
        })
    }
}

/// `A^-1 B A^-1` (row-major q x q) for the Jacobian `columns` (each `n`
/// long) and residuals `r`, whose index `k` is time `k % length`; and the
/// bandwidth used.
fn sandwich(
    columns: &[f64],
    r: &[f64],
    q: usize,
    length: usize,
) -> Result<(Vec<f64>, usize), Error> {
    let n = r.len();
    // The scores per time: g_t = sum over the blocks of J_k' r_k.
    let mut scores = vec![0.0; length * q];
    for a in 0..q {
        let column = &columns[a * n..(a + 1) * n];
        for (k, (j, e)) in column.iter().zip(r).enumerate() {
            scores[(k % length) * q + a] += j * e;
        }
    }
    // Prewhitened (Andrews and Monahan, 1992, Econometrica 60(4)): each
    // score series' AR(1) part is taken out, the kernel estimate made on
    // what is left, and the AR(1) part put back; the kernel estimate alone
    // is far too narrow for strongly correlated series.
    let rho: Vec<f64> = (0..q)
        .map(|a| {
            let (mut lagged, mut square) = (0.0, 0.0);
            for t in 1..length {
                lagged += scores[t * q + a] * scores[(t - 1) * q + a];
                square += scores[(t - 1) * q + a] * scores[(t - 1) * q + a];
            }
            // Bounded away from a unit root, where nothing is estimable.
            if square > 0.0 {
                (lagged / square).clamp(-0.97, 0.97)
            } else {
                0.0
            }
        })
        .collect();
    // The first score has no predecessor: it stands as it is.
    let whitened: Vec<f64> = (0..length)
        .flat_map(|t| {
            let (rho, scores) = (&rho, &scores);
            (0..q).map(move |a| {
                let before = if t > 0 { scores[(t - 1) * q + a] } else { 0.0 };
                scores[t * q + a] - rho[a] * before
            })
        })
        .collect();
    let bandwidth = andrews_bandwidth(&whitened, q, length);
    let mut meat = vec![0.0; q * q];
    for lag in 0..=bandwidth {
        let weight = 1.0 - lag as f64 / (bandwidth + 1) as f64;
        for t in lag..length {
            let now = &whitened[t * q..(t + 1) * q];
            let then = &whitened[(t - lag) * q..(t - lag + 1) * q];
            for a in 0..q {
                for b in 0..q {
                    let product = now[a] * then[b];
                    meat[a * q + b] += if lag == 0 {
                        product
                    } else {
                        // Gamma_l + Gamma_l': both orders of the pair.
                        weight * (product + then[a] * now[b])
                    };
                }
            }
        }
    }
    // Recoloured.
    for a in 0..q {
        for b in 0..q {
            meat[a * q + b] /= (1.0 - rho[a]) * (1.0 - rho[b]);
        }
    }
    // A small-sample correction: q parameters were fitted to the residuals.
    let correction = length as f64 / (length.saturating_sub(q).max(1)) as f64;
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
    let mut factor = bread;
    cholesky_in_place(&mut factor, q, PivotRule::RelativeToLargest(1e-12)).map_err(|_| {
        Error::Numerical {
            what: "the residuals do not change with some parameter near the estimate: the record \
                   does not determine it, and it has no interval"
                .into(),
        }
    })?;
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
        for b in 0..q {
            covariance[a * q + b] = correction * row[b];
        }
    }
    Ok((covariance, bandwidth))
}

/// Andrews' bandwidth for the Bartlett kernel from AR(1) fits of each
/// series (`length` rows of `q`): `1.1447 (alpha T)^(1/3)` with `alpha = sum 4 rho^2 s^4 / ((1 -
/// rho)^6 (1 + rho)^2) / sum s^4 / (1 - rho)^4`, below the series length.
fn andrews_bandwidth(series_rows: &[f64], q: usize, length: usize) -> usize {
    if length < 3 {
        return 0;
    }
    let (mut numerator, mut denominator) = (0.0, 0.0);
    for a in 0..q {
        let series = |t: usize| series_rows[t * q + a];
        let (mut lagged, mut square) = (0.0, 0.0);
        for t in 1..length {
            lagged += series(t) * series(t - 1);
            square += series(t - 1) * series(t - 1);
        }
        if square <= 0.0 {
            continue;
        }
        // Bounded away from a unit root, where the rule has no answer.
        let rho = (lagged / square).clamp(-0.97, 0.97);
        let innovation = (1..length)
            .map(|t| (series(t) - rho * series(t - 1)).powi(2))
            .sum::<f64>()
            / (length - 1) as f64;
        let s4 = innovation * innovation;
        numerator += 4.0 * rho * rho * s4 / ((1.0 - rho).powi(6) * (1.0 + rho).powi(2));
        denominator += s4 / (1.0 - rho).powi(4);
    }
    if denominator <= 0.0 {
        return 0;
    }
    let alpha = numerator / denominator;
    let bandwidth = 1.1447 * (alpha * length as f64).cbrt();
    (bandwidth.floor() as usize).min(length - 1)
}
