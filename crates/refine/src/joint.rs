//! One parameter vector of a plant from several of its records, each on
//! its own input: the single-record estimates pooled by their intervals,
//! then one best-fit search of the sum of every record's loss, started
//! from the pooled estimate, its interval's corners, each single estimate
//! and the prior, with the joint interval from the records' residuals
//! together (the multi-experiment fit of system identification).

use crate::InvalidSetting;
use twostage_models::{IoData, Prior, standard_normal_quantile};

use crate::RefineError;
use crate::best_fit::{BestFit, SearchStarts};
use crate::between::BetweenRecords;
use crate::refinement::{Refinement, ResidualModel};
use crate::uncertainty::{LocalUncertainty, local_uncertainty};

/// One record with its own estimate, as [`Refinement::joint_estimate`]
/// pools it: the estimate's interval half-widths where it has them.
#[derive(Debug, Clone, Copy)]
pub struct SingleEstimate<'a> {
    /// The record.
    pub record: &'a IoData,
    /// Its estimate from it alone.
    pub theta: &'a [f64],
    /// That estimate's interval half-widths, at the plan's level.
    pub half_widths: Option<&'a [f64]>,
}

/// How [`Refinement::joint_estimate`] searches and states its answer.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `search` | [`SearchStarts::default_from_prior`] starts from the prior | any |
/// | `alpha` | 0.1 (90% intervals) | in (0, 1) |
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointPlan {
    /// The starts drawn over the prior, besides the pooled estimate, its
    /// interval's corners and the single estimates.
    pub search: SearchStarts,
    /// The level `1 - alpha` of the single estimates' intervals, and of
    /// the joint interval.
    pub alpha: f64,
}

/// The single estimates pooled: see [`pool_estimates`].
#[derive(Debug, Clone, PartialEq)]
pub struct PooledEstimate {
    /// Per parameter, the mean of the single estimates that have an
    /// interval, weighted by the inverse square of their half-widths (the
    /// plain mean of all where none has one).
    pub theta: Vec<f64>,
    /// The pooled half-widths, `(sum 1 / w_i^2)^(-1/2)`, as if the single
    /// estimates' errors were independent (`None` without intervals): the
    /// spread of the search's first starts, not a stated interval.
    pub half_widths: Option<Vec<f64>>,
    /// The records whose single estimate lies beyond its interval from
    /// the weighted median of the estimates with intervals (a centre that
    /// a minority of disagreeing records does not move), the interval
    /// widened to hold for every parameter of every record at once
    /// (Bonferroni: the level `1 - alpha / (q n)`); of two, both when
    /// they lie beyond their intervals combined from each other.
    pub disagreeing: Vec<usize>,
}

/// Pools single estimates `(theta, half_widths)` of one plant, their
/// intervals at level `1 - alpha`: see [`PooledEstimate`].
///
/// ```
/// use twostage_refine::pool_estimates;
/// // Two estimates of equal width average; a third, four times as sure,
/// // weighs sixteen times as much. None disagrees at the 90% level.
/// let w = [1.0];
/// let pooled = pool_estimates(&[(&[1.0][..], Some(&w[..])), (&[2.0], Some(&w)), (&[1.5], Some(&[0.25]))], 0.1)?;
/// assert!((pooled.theta[0] - 1.5).abs() < 1e-12);
/// assert!((pooled.half_widths.unwrap()[0] - (1.0f64 / 18.0).sqrt()).abs() < 1e-12);
/// assert!(pooled.disagreeing.is_empty());
/// // An estimate 10 half-widths away from two others disagrees; they do not.
/// let far = pool_estimates(&[(&[1.0][..], Some(&w[..])), (&[1.0], Some(&w)), (&[11.0], Some(&w))], 0.1)?;
/// assert_eq!(far.disagreeing, [2]);
/// # Ok::<(), twostage_refine::RefineError>(())
/// ```
///
/// # Errors
/// No estimate, estimates or half-widths of different lengths, or a level
/// outside (0, 1).
pub fn pool_estimates(
    singles: &[(&[f64], Option<&[f64]>)],
    alpha: f64,
) -> Result<PooledEstimate, RefineError> {
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(RefineError::InvalidSetting(InvalidSetting {
            name: "alpha",
            value: alpha.to_string(),
            reason: "the intervals' level 1 - alpha needs alpha in (0, 1)".into(),
        }));
    }
    let Some((first, _)) = singles.first() else {
        return Err(RefineError::InvalidSetting(InvalidSetting {
            name: "records",
            value: "none".into(),
            reason: "a joint estimate needs at least one record".into(),
        }));
    };
    let q = first.len();
    for (theta, widths) in singles {
        for (what, found) in [
            ("a single estimate", Some(theta.len())),
            ("a single estimate's half-widths", widths.map(<[f64]>::len)),
        ] {
            if let Some(found) = found.filter(|n| *n != q) {
                return Err(RefineError::Length {
                    what,
                    found,
                    expected: q,
                });
            }
        }
    }
    // Only estimates with a usable interval weigh in, and only they can
    // disagree: an estimate without one (out of the estimator's
    // distribution, say) is a start of the search, nothing more.
    let sure: Vec<(usize, &[f64], &[f64])> = singles
        .iter()
        .enumerate()
        .filter_map(|(i, (t, w))| {
            let w = w.filter(|w| w.iter().all(|v| v.is_finite() && *v > 0.0))?;
            Some((i, *t, w))
        })
        .collect();
    if sure.is_empty() {
        let n = singles.len() as f64;
        let theta = (0..q)
            .map(|j| singles.iter().map(|(t, _)| t[j]).sum::<f64>() / n)
            .collect();
        return Ok(PooledEstimate {
            theta,
            half_widths: None,
            disagreeing: Vec::new(),
        });
    }
    let mut theta = vec![0.0; q];
    let mut pooled_widths = vec![0.0; q];
    for j in 0..q {
        let precision: f64 = sure.iter().map(|(_, _, w)| 1.0 / (w[j] * w[j])).sum();
        let weighted: f64 = sure.iter().map(|(_, t, w)| t[j] / (w[j] * w[j])).sum();
        theta[j] = weighted / precision;
        pooled_widths[j] = 1.0 / precision.sqrt();
    }
    let n = sure.len() as f64;
    let widen = standard_normal_quantile(1.0 - alpha / (2.0 * q as f64 * n))
        / standard_normal_quantile(1.0 - alpha / 2.0);
    let disagreeing = if let [(a, ta, wa), (b, tb, wb)] = sure[..] {
        // Two cannot say which of them is off: both are named.
        let apart = (0..q).any(|j| (ta[j] - tb[j]).abs() > widen * wa[j].hypot(wb[j]));
        if apart { vec![a, b] } else { Vec::new() }
    } else {
        let centre: Vec<f64> = (0..q)
            .map(|j| {
                weighted_median(
                    sure.iter()
                        .map(|(_, t, w)| (t[j], 1.0 / (w[j] * w[j])))
                        .collect(),
                )
            })
            .collect();
        sure.iter()
            .filter(|(_, t, w)| (0..q).any(|j| (t[j] - centre[j]).abs() > widen * w[j]))
            .map(|(i, _, _)| *i)
            .collect()
    };
    Ok(PooledEstimate {
        theta,
        half_widths: Some(pooled_widths),
        disagreeing,
    })
}

/// The smallest value whose weights, with those of the values below it,
/// reach half the total.
fn weighted_median(mut values: Vec<(f64, f64)>) -> f64 {
    values.sort_by(|a, b| a.0.total_cmp(&b.0));
    let half = values.iter().map(|(_, w)| w).sum::<f64>() / 2.0;
    let mut below = 0.0;
    for (value, weight) in &values {
        below += weight;
        if below >= half {
            return *value;
        }
    }
    values.last().map_or(f64::NAN, |(v, _)| *v)
}

/// What [`Refinement::joint_estimate`] found.
#[derive(Debug, Clone)]
pub struct JointEstimate<E> {
    /// The joint estimate: the best fit of every fitted record together.
    pub theta: Vec<f64>,
    /// Its uncertainty from the records' residuals (each record's outputs
    /// their own noise model), each sd at least the joint sd under the
    /// scatter between the records ([`BetweenRecords::joint_sd`]), or why
    /// it has none.
    pub uncertainty: Result<LocalUncertainty, E>,
    /// The single estimates pooled, which the search started from.
    pub pooled: PooledEstimate,
    /// The search of the records' summed loss.
    pub search: BestFit,
    /// The records fitted, by their place among the single estimates.
    pub fitted: Vec<usize>,
    /// The records left out, by place, with why the model could not be
    /// run on them (at the pooled estimate).
    pub left_out: Vec<(usize, E)>,
    /// Each fitted record's own loss at the joint estimate, in the order
    /// of `fitted` (`None` where the interval's evaluations failed).
    pub record_losses: Option<Vec<f64>>,
    /// How far the records' own best fits scatter about the joint
    /// estimate beyond their noise (`None` with fewer than two records
    /// that determine every parameter, or where the interval's
    /// evaluations failed).
    pub between: Option<BetweenRecords>,
}

impl<M: ResidualModel> Refinement<M> {
    /// One estimate of the plant behind every record of `singles`, each
    /// simulated on its own input: the single estimates pooled
    /// ([`pool_estimates`]), then the best fit of the sum of the records'
    /// losses from the pooled estimate, the corners of its interval, every
    /// single estimate and `plan.search`'s starts over the prior, in one
    /// lockstep ([`Refinement::best_fits`]); its interval is the sandwich
    /// of [`Refinement::uncertainty`] over all the records' residuals. A
    /// record the model cannot run at the pooled estimate is left out and
    /// named; the others are fitted.
    ///
    /// ```
    /// # use twostage_models::{IoData, Prior};
    /// # use twostage_refine::{RefineError, Refinement, ResidualModel};
    /// # struct ConstantMean(Prior);
    /// # impl ResidualModel for ConstantMean {
    /// #     type Error = RefineError;
    /// #     fn prior(&self) -> &Prior { &self.0 }
    /// #     fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
    /// #         for (r, y) in r.iter_mut().zip(record.output(0)) { *r = y - theta[0]; }
    /// #         Ok(())
    /// #     }
    /// # }
    /// use twostage_refine::{JointPlan, SearchStarts, SingleEstimate};
    /// let fit = Refinement::new(ConstantMean(Prior::uniform_box(&[0.0], &[1.0])?));
    /// let a = IoData::siso(&[0.0; 2], &[0.2, 0.4])?;
    /// let b = IoData::siso(&[0.0; 4], &[0.5, 0.5, 0.6, 0.6])?;
    /// let singles = [
    ///     SingleEstimate { record: &a, theta: &[0.3], half_widths: Some(&[0.1]) },
    ///     SingleEstimate { record: &b, theta: &[0.55], half_widths: Some(&[0.05]) },
    /// ];
    /// let plan = JointPlan { search: SearchStarts { from_prior: 2, seed: 0 }, alpha: 0.1 };
    /// let joint = fit.joint_estimate(&singles, plan)?;
    /// // The mean of all six samples, 2.8 / 6.
    /// assert!((joint.theta[0] - 2.8 / 6.0).abs() < 1e-6);
    /// assert_eq!(joint.fitted, [0, 1]);
    /// assert!(joint.uncertainty.is_ok());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// No record, estimates of the wrong length, a level outside (0, 1),
    /// or a model that runs on none of the records.
    pub fn joint_estimate(
        &self,
        singles: &[SingleEstimate<'_>],
        plan: JointPlan,
    ) -> Result<JointEstimate<M::Error>, M::Error> {
        let prior = self.model().prior();
        let estimates: Vec<(&[f64], Option<&[f64]>)> =
            singles.iter().map(|s| (s.theta, s.half_widths)).collect();
        let pooled = pool_estimates(&estimates, plan.alpha)?;
        if pooled.theta.len() != prior.dim() {
            return Err(RefineError::Length {
                what: "the single estimates",
                found: pooled.theta.len(),
                expected: prior.dim(),
            }
            .into());
        }
        let (fitted, left_out) = self.runnable(singles, &pooled.theta);
        let Some(&nominal) = fitted.first().map(|&i| &singles[i].record) else {
            let (_, first) = left_out
                .into_iter()
                .next()
                .unwrap_or_else(|| unreachable!("a record is fitted or left out"));
            return Err(first);
        };
        let mut starts = plan
            .search
            .starts(prior, &pooled.theta, pooled.half_widths.as_deref())?;
        starts.extend(fitted.iter().map(|&i| singles[i].theta.to_vec()));
        let together = Refinement::new(Together {
            model: self.model(),
            records: fitted.iter().map(|&i| singles[i].record).collect(),
        })
        .max_iterations(self.iterations());
        let search = together
            .best_fits(vec![(nominal, starts)])
            .pop()
            .unwrap_or_else(|| unreachable!("one search, one result"))?;
        let theta = search.best.theta.clone();
        let at_best = together
            .linearizations(&[(nominal, &theta)])
            .pop()
            .unwrap_or_else(|| unreachable!("one estimate, one result"));
        let (mut uncertainty, record_losses, between) = match at_best {
            Ok(at) => {
                let span = self.span();
                let local = at.covariance().map(|(covariance, noise_order)| {
                    local_uncertainty(&covariance, &span, noise_order)
                });
                let mut losses = Vec::with_capacity(fitted.len());
                let mut steps = Vec::with_capacity(fitted.len());
                let mut from = 0;
                for record in &together.model().records {
                    let n = self.model().n_residuals(record);
                    let mine = &at.residuals[from..from + n];
                    losses.push(mine.iter().map(|r| r * r).sum());
                    let mut runs = self.model().residual_runs(record);
                    if runs.iter().sum::<usize>() != n {
                        runs = vec![n];
                    }
                    // A record whose own loss leaves some parameter free
                    // has no own best fit to scatter.
                    if let Ok(step) = at.part(from, n, runs).own_step() {
                        steps.push(step);
                    }
                    from += n;
                }
                let between = BetweenRecords::of_steps(&steps, &span);
                (local.map_err(M::Error::from), Some(losses), between)
            }
            Err(e) => (Err(e), None, None),
        };
        if let (Ok(local), Some(between)) = (&mut uncertainty, &between) {
            for (sd, joint) in local.sd.iter_mut().zip(&between.joint_sd) {
                *sd = sd.max(*joint);
            }
        }
        Ok(JointEstimate {
            theta,
            uncertainty,
            pooled,
            search,
            fitted,
            left_out,
            record_losses,
            between,
        })
    }

    /// The records the model runs on at `theta` (by place), and those it
    /// does not, with why: all of them asked for in one batch.
    fn runnable(
        &self,
        singles: &[SingleEstimate<'_>],
        theta: &[f64],
    ) -> (Vec<usize>, Vec<(usize, M::Error)>) {
        let pairs: Vec<(&[f64], &IoData)> = singles.iter().map(|s| (theta, s.record)).collect();
        let mut values = vec![Vec::new(); pairs.len()];
        let mut fitted = Vec::new();
        let mut left_out = Vec::new();
        for (i, answer) in self
            .model()
            .residuals_batch(&pairs, &mut values)
            .into_iter()
            .enumerate()
        {
            match answer {
                Ok(()) => fitted.push(i),
                Err(e) => left_out.push((i, e)),
            }
        }
        (fitted, left_out)
    }
}

/// Several records as one: the residuals of each record in turn, at the
/// same parameters. The record a search hands it stands for them all.
struct Together<'a, M> {
    model: &'a M,
    records: Vec<&'a IoData>,
}

impl<M: ResidualModel> ResidualModel for Together<'_, M> {
    type Error = M::Error;

    fn prior(&self) -> &Prior {
        self.model.prior()
    }

    fn residuals(&self, theta: &[f64], _: &IoData, residuals: &mut [f64]) -> Result<(), M::Error> {
        let mut rest = residuals;
        for record in &self.records {
            let (mine, after) = rest.split_at_mut(self.model.n_residuals(record));
            self.model.residuals(theta, record, mine)?;
            rest = after;
        }
        Ok(())
    }

    fn n_residuals(&self, _: &IoData) -> usize {
        self.records.iter().map(|r| self.model.n_residuals(r)).sum()
    }

    fn residual_runs(&self, _: &IoData) -> Vec<usize> {
        self.records
            .iter()
            .flat_map(|r| self.model.residual_runs(r))
            .collect()
    }

    /// Every point on every record in one batch of the model's, so that a
    /// simulator gets each record's points together.
    fn residuals_batch(
        &self,
        pairs: &[(&[f64], &IoData)],
        residuals: &mut [Vec<f64>],
    ) -> Vec<Result<(), M::Error>> {
        let each: Vec<(&[f64], &IoData)> = pairs
            .iter()
            .flat_map(|(theta, _)| self.records.iter().map(move |record| (*theta, *record)))
            .collect();
        let mut parts = vec![Vec::new(); each.len()];
        let mut answers = self.model.residuals_batch(&each, &mut parts).into_iter();
        let mut parts = parts.into_iter();
        let per_point = self.records.len();
        residuals
            .iter_mut()
            .map(|r| {
                r.clear();
                let mut failed = None;
                for (answer, part) in answers.by_ref().take(per_point).zip(parts.by_ref()) {
                    match answer {
                        Ok(()) => r.extend_from_slice(&part),
                        Err(e) => failed = failed.or(Some(e)),
                    }
                }
                failed.map_or(Ok(()), Err)
            })
            .collect()
    }

    fn trials_at_once(&self) -> usize {
        self.model.trials_at_once()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every output is `theta` plus noise: residuals `y_j - theta` per
    /// output, each a run of its own.
    struct ConstantOutputs(Prior);

    impl ResidualModel for ConstantOutputs {
        type Error = RefineError;
        fn prior(&self) -> &Prior {
            &self.0
        }
        fn n_residuals(&self, record: &IoData) -> usize {
            record.n_samples() * record.n_outputs()
        }
        fn residuals(
            &self,
            theta: &[f64],
            record: &IoData,
            r: &mut [f64],
        ) -> Result<(), Self::Error> {
            let n = record.n_samples();
            for j in 0..record.n_outputs() {
                for (r, y) in r[j * n..(j + 1) * n].iter_mut().zip(record.output(j)) {
                    *r = y - theta[0];
                }
            }
            Ok(())
        }
    }

    /// Two one-output records together are one record of two outputs: the
    /// same best fit and the same interval, each output (record) with its
    /// own noise model.
    #[test]
    fn two_records_together_are_one_record_of_two_outputs() {
        let n = 300;
        // Two sequences of different spread and colour, deterministic.
        let a: Vec<f64> = (0..n)
            .map(|t| 1.0 + 0.3 * ((t * t % 17) as f64 / 8.0 - 1.0))
            .collect();
        let b: Vec<f64> = (0..n)
            .map(|t| 1.2 + 0.1 * ((t as f64) * 0.37).sin())
            .collect();
        let u = vec![0.0; n];
        let first = IoData::siso(&u, &a).unwrap();
        let second = IoData::siso(&u, &b).unwrap();
        let mut both = IoData::default();
        both.resize(n, 1, 2);
        both.output_mut(0).copy_from_slice(&a);
        both.output_mut(1).copy_from_slice(&b);
        let fit = Refinement::new(ConstantOutputs(Prior::uniform_box(&[0.0], &[3.0]).unwrap()));
        let singles = [
            SingleEstimate {
                record: &first,
                theta: &[1.0],
                half_widths: Some(&[0.1]),
            },
            SingleEstimate {
                record: &second,
                theta: &[1.2],
                half_widths: Some(&[0.1]),
            },
        ];
        let plan = JointPlan {
            search: SearchStarts {
                from_prior: 3,
                seed: 0,
            },
            alpha: 0.1,
        };
        let joint = fit.joint_estimate(&singles, plan).unwrap();
        let mean = (a.iter().sum::<f64>() + b.iter().sum::<f64>()) / (2 * n) as f64;
        assert!(
            (joint.theta[0] - mean).abs() < 1e-9,
            "{} vs {mean}",
            joint.theta[0]
        );
        let alone = fit.uncertainty(&both, &joint.theta).unwrap();
        let together = joint.uncertainty.unwrap();
        // Each record's own best fit is its mean, with its own interval
        // there: their scatter by the moment estimate, computed apart.
        let own: Vec<(f64, f64)> = [&a, &b]
            .into_iter()
            .zip([&first, &second])
            .map(|(y, record)| {
                let m = y.iter().sum::<f64>() / n as f64;
                (m, fit.uncertainty(record, &[m]).unwrap().sd[0].powi(2))
            })
            .collect();
        let (means, variances): (Vec<f64>, Vec<f64>) = own.into_iter().unzip();
        let tau2 = crate::between_record_variance(&means, &variances).unwrap();
        let between = joint.between.unwrap();
        assert!(
            (between.sd[0] - tau2.sqrt()).abs() <= 1e-6 * tau2.sqrt(),
            "{between:?} against tau^2 {tau2}"
        );
        let under_scatter = 1.0
            / variances
                .iter()
                .map(|v| 1.0 / (v + tau2))
                .sum::<f64>()
                .sqrt();
        assert!((between.joint_sd[0] - under_scatter).abs() <= 1e-6 * under_scatter);
        // The means lie 0.2 apart, far beyond their noise: the scatter
        // sets the joint sd, wider than the sandwich of one record of two
        // outputs (which sees the offsets as slow noise).
        assert_eq!(between.mismatch_sets_width(), [true]);
        assert!(
            under_scatter > 1.5 * alone.sd[0],
            "{under_scatter} {alone:?}"
        );
        assert_eq!(together.sd[0].to_bits(), between.joint_sd[0].to_bits());
        assert_eq!(together.noise_order, alone.noise_order);
        // The records' own losses add up to the search's.
        let losses = joint.record_losses.unwrap();
        let direct: f64 = a.iter().map(|y| (y - joint.theta[0]).powi(2)).sum();
        assert!((losses[0] - direct).abs() < 1e-9 * direct);
    }
}
