//! One parameter vector of a plant from several of its records, each on
//! its own input: the single-record estimates pooled by their intervals,
//! then one best-fit search of the sum of every record's loss, started
//! from the pooled estimate, its interval's corners, each single estimate
//! and the prior, with the joint interval from the records' residuals
//! together (the multi-experiment fit of system identification).

use crate::InvalidSetting;
use twostage_models::{IoData, standard_normal_quantile};

use crate::RefineError;
use crate::best_fit::{BestFit, SearchStarts};
use crate::between::BetweenRecords;
use crate::refinement::{Refinement, ResidualModel};
use crate::together::Together;
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
    /// The joint estimate: the best fit of every fitted record together
    /// (NaN at the records' own parameters, which have no one value).
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
    /// evaluations failed); zero on the records' own parameters.
    pub between: Option<BetweenRecords>,
    /// Each fitted record's whole parameter vector at the joint estimate,
    /// in the order of `fitted`: the plant's parameters the joint
    /// estimate's, its own parameters its own (each equal to `theta`
    /// without own parameters).
    pub records_theta: Vec<Vec<f64>>,
    /// Each fitted record's uncertainty of `records_theta` (`None` where
    /// `uncertainty` has none).
    pub records_uncertainty: Option<Vec<LocalUncertainty>>,
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
        let q = self.model().prior().dim();
        self.joint_estimate_with_own(singles, plan, &vec![false; q])
    }

    /// [`Refinement::joint_estimate`] of a model whose parameters marked in
    /// `per_record` (one flag each, in order) belong to each record (an
    /// initial state, a sensor offset): the records share the others, and
    /// each gets its own value of these, fitted with the rest in one
    /// search of the joint vector (the plant's parameters once, each
    /// record's own once per record). The joint estimate's entries of the
    /// records' own parameters are NaN: each record's whole vector is in
    /// [`JointEstimate::records_theta`], with its interval. The records'
    /// single estimates are pooled, and judged to disagree, on the
    /// plant's parameters alone.
    ///
    /// ```
    /// # use twostage_models::{IoData, Prior};
    /// # use twostage_refine::{RefineError, Refinement, ResidualModel};
    /// // The output is a gain times the input plus the record's own offset.
    /// struct GainAndOffset(Prior);
    /// impl ResidualModel for GainAndOffset {
    ///     type Error = RefineError;
    ///     fn prior(&self) -> &Prior { &self.0 }
    ///     fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
    ///         for ((r, u), y) in r.iter_mut().zip(record.input(0)).zip(record.output(0)) {
    ///             *r = y - theta[0] * u - theta[1];
    ///         }
    ///         Ok(())
    ///     }
    /// }
    /// use twostage_refine::{JointPlan, SearchStarts, SingleEstimate};
    /// let fit = Refinement::new(GainAndOffset(Prior::uniform_box(&[0.0, -5.0], &[5.0, 5.0])?));
    /// let a = IoData::siso(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0])?; // gain 2, offset 0
    /// let b = IoData::siso(&[1.0, 0.0, 2.0], &[3.0, 1.0, 5.0])?; // gain 2, offset 1
    /// let singles = [
    ///     SingleEstimate { record: &a, theta: &[1.8, 0.2], half_widths: None },
    ///     SingleEstimate { record: &b, theta: &[2.2, 0.8], half_widths: None },
    /// ];
    /// let plan = JointPlan { search: SearchStarts { from_prior: 2, seed: 0 }, alpha: 0.1 };
    /// let joint = fit.joint_estimate_with_own(&singles, plan, &[false, true])?;
    /// assert!((joint.theta[0] - 2.0).abs() < 1e-6 && joint.theta[1].is_nan());
    /// assert!((joint.records_theta[0][1] - 0.0).abs() < 1e-6);
    /// assert!((joint.records_theta[1][1] - 1.0).abs() < 1e-6);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// As [`Refinement::joint_estimate`], and flags of another count than
    /// the parameters'.
    pub fn joint_estimate_with_own(
        &self,
        singles: &[SingleEstimate<'_>],
        plan: JointPlan,
        per_record: &[bool],
    ) -> Result<JointEstimate<M::Error>, M::Error> {
        let prior = self.model().prior();
        let q = prior.dim();
        if per_record.len() != q {
            return Err(RefineError::Length {
                what: "the per-record flags",
                found: per_record.len(),
                expected: q,
            }
            .into());
        }
        for single in singles {
            if single.theta.len() != q {
                return Err(RefineError::Length {
                    what: "a single estimate",
                    found: single.theta.len(),
                    expected: q,
                }
                .into());
            }
        }
        // Pooled, and judged, on the plant's parameters: the records' own
        // differ by design.
        let shared: Vec<usize> = (0..q).filter(|&j| !per_record[j]).collect();
        let pick = |v: &[f64]| -> Vec<f64> { shared.iter().map(|&j| v[j]).collect() };
        let picked: Vec<(Vec<f64>, Option<Vec<f64>>)> = singles
            .iter()
            .map(|s| (pick(s.theta), s.half_widths.map(pick)))
            .collect();
        let estimates: Vec<(&[f64], Option<&[f64]>)> = picked
            .iter()
            .map(|(t, w)| (t.as_slice(), w.as_deref()))
            .collect();
        let pooled = if shared.is_empty() {
            PooledEstimate {
                theta: Vec::new(),
                half_widths: None,
                disagreeing: Vec::new(),
            }
        } else {
            pool_estimates(&estimates, plan.alpha)?
        };
        let spread = |shared_values: &[f64], fill: f64| -> Vec<f64> {
            let mut whole = vec![fill; q];
            for (&j, v) in shared.iter().zip(shared_values) {
                whole[j] = *v;
            }
            whole
        };
        let pooled = PooledEstimate {
            theta: spread(&pooled.theta, f64::NAN),
            half_widths: pooled.half_widths.map(|w| spread(&w, f64::NAN)),
            disagreeing: pooled.disagreeing,
        };
        // Each record at the pooled plant and its own estimate's own part.
        let at_pooled: Vec<Vec<f64>> = singles
            .iter()
            .map(|s| {
                let mut theta = s.theta.to_vec();
                for &j in &shared {
                    theta[j] = pooled.theta[j];
                }
                theta
            })
            .collect();
        let (fitted, left_out) = self.runnable(singles, &at_pooled);
        let Some(&nominal) = fitted.first().map(|&i| &singles[i].record) else {
            let (_, first) = left_out
                .into_iter()
                .next()
                .unwrap_or_else(|| unreachable!("a record is fitted or left out"));
            return Err(first);
        };
        let together = Refinement::new(Together::new(
            self.model(),
            fitted.iter().map(|&i| singles[i].record).collect(),
            per_record,
        )?)
        .max_iterations(self.iterations());
        let layout = together.model().layout.clone();
        let joint_of = |plant: &[f64]| layout.joint_vector(plant, |r| singles[fitted[r]].theta);
        // The pooled interval spreads the first starts; with own
        // parameters, where every fitted record has their interval too.
        let joint_widths = pooled.half_widths.as_ref().and_then(|w| {
            if !layout.has_own() {
                return Some(w.clone());
            }
            let own: Option<Vec<&[f64]>> = fitted.iter().map(|&i| singles[i].half_widths).collect();
            own.map(|own| layout.joint_vector(w, |r| own[r]))
        });
        let mut starts = plan.search.starts(
            together.model().prior(),
            &joint_of(&at_pooled[fitted[0]]),
            joint_widths.as_deref(),
        )?;
        starts.extend(fitted.iter().map(|&i| joint_of(singles[i].theta)));
        let search = together
            .best_fits(vec![(nominal, starts)])
            .pop()
            .unwrap_or_else(|| unreachable!("one search, one result"))?;
        let joint = search.best.theta.clone();
        let records_theta: Vec<Vec<f64>> = (0..fitted.len())
            .map(|r| layout.record_theta(&joint, r))
            .collect();
        let at_best = together
            .linearizations(&[(nominal, &joint)])
            .pop()
            .unwrap_or_else(|| unreachable!("one estimate, one result"));
        let span = self.span();
        let (mut records_uncertainty, record_losses, between) = match at_best {
            Ok(at) => {
                let joint_span = together.span();
                let local = at.covariance().map(|(covariance, noise_order)| {
                    let whole = local_uncertainty(&covariance, &joint_span, noise_order);
                    (0..fitted.len())
                        .map(|r| whole.of(&layout.places(r)))
                        .collect::<Vec<_>>()
                });
                let mut losses = Vec::with_capacity(fitted.len());
                let mut steps = Vec::with_capacity(fitted.len());
                let mut from = 0;
                let plant_places = &layout.places(0)[..];
                let plant_places: Vec<usize> = shared.iter().map(|&j| plant_places[j]).collect();
                for (r, record) in together.model().records.iter().enumerate() {
                    let n = self.model().n_residuals(record);
                    let mine = &at.residuals[from..from + n];
                    losses.push(mine.iter().map(|r| r * r).sum());
                    let mut runs = self.model().residual_runs(record);
                    if runs.iter().sum::<usize>() != n {
                        runs = vec![n];
                    }
                    let part = at.part(from, n, runs);
                    // A record's own best fit moves its own parameters
                    // too; only the plant's scatter between records.
                    let part = if layout.has_own() {
                        let places = layout.places(r);
                        let mut keep = plant_places.clone();
                        keep.extend(layout.own.iter().map(|&j| places[j]));
                        part.columns_of(&keep)
                    } else {
                        part
                    };
                    // A record whose own loss leaves some parameter free
                    // has no own best fit to scatter.
                    if let Ok((step, covariance)) = part.own_step() {
                        let width = step.len();
                        let s = shared.len();
                        steps.push((
                            step[..s].to_vec(),
                            (0..s * s)
                                .map(|k| covariance[(k / s) * width + k % s])
                                .collect(),
                        ));
                    }
                    from += n;
                }
                let plant_span: Vec<f64> = shared.iter().map(|&j| span[j]).collect();
                let between = BetweenRecords::of_steps(&steps, &plant_span)
                    .map(|b| b.of_parameters(&shared, q));
                (local.map_err(M::Error::from), Some(losses), between)
            }
            Err(e) => (Err(e), None, None),
        };
        if let (Ok(records), Some(between)) = (&mut records_uncertainty, &between) {
            for local in records {
                for (sd, joint) in local.sd.iter_mut().zip(&between.joint_sd) {
                    *sd = sd.max(*joint);
                }
            }
        }
        // The plant's view: a record's own parameters have no one value.
        let own_nan = |v: &[f64]| -> Vec<f64> {
            (0..q)
                .map(|j| if per_record[j] { f64::NAN } else { v[j] })
                .collect()
        };
        let theta = own_nan(&records_theta[0]);
        let (uncertainty, records_uncertainty) = match records_uncertainty {
            Ok(records) => (Ok(records[0].without(per_record)), Some(records)),
            Err(e) => (Err(e), None),
        };
        Ok(JointEstimate {
            theta,
            uncertainty,
            pooled,
            search,
            fitted,
            left_out,
            record_losses,
            between,
            records_theta,
            records_uncertainty,
        })
    }

    /// The records the model runs on, each at its `thetas` (by place), and those it
    /// does not, with why: all of them asked for in one batch.
    fn runnable(
        &self,
        singles: &[SingleEstimate<'_>],
        thetas: &[Vec<f64>],
    ) -> (Vec<usize>, Vec<(usize, M::Error)>) {
        let pairs: Vec<(&[f64], &IoData)> = singles
            .iter()
            .zip(thetas)
            .map(|(s, theta)| (theta.as_slice(), s.record))
            .collect();
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

#[cfg(test)]
mod tests;
