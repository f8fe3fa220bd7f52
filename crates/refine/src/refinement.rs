//! Refining a two-stage estimate with the model's likelihood, where one is
//! known: Levenberg-Marquardt descents of the prediction-error loss confined
//! to a neighbourhood of the estimate ([`Refinement::refine`]), or the
//! posterior mean over that neighbourhood ([`Refinement::local_posterior`]).
//! TS picks the neighbourhood (its calibrated intervals,
//! the estimator's `neighbourhood`), the
//! likelihood finds the answer inside it.
//!
//! The same descent, started from draws of the prior instead, is the
//! prediction-error method of the paper's Section 2.2; the baselines build
//! it (and indirect inference) on [`Refinement::descend`].

use crate::InvalidSetting;
use twostage_models::IoData;

use crate::error::RefineError as Error;
use crate::lockstep::{self, DescentJob};
use crate::moments::WeightedMoments;
pub use crate::residual::{Descent, ResidualModel};

/// The result of [`Refinement::local_posterior`].
#[derive(Debug, Clone, PartialEq)]
pub struct LocalPosterior {
    /// The posterior mean over the box.
    pub mean: Vec<f64>,
    /// The posterior standard deviation over the box, at least the grid's
    /// resolution (a uniform cell's, spacing / sqrt 12).
    pub sd: Vec<f64>,
    /// The posterior correlation matrix (row-major q x q).
    pub correlation: Vec<f64>,
    /// Loss evaluations spent.
    pub evaluations: usize,
}

/// Where [`Refinement::refine`] starts its descents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefineStarts {
    /// One descent from the given start.
    Centre,
    /// That, and one from each side of it along each axis.
    CentreAndAxes,
}

/// Local searches of a [`ResidualModel`]'s loss in its prior box.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `max_iterations` | 50 | >= 1 per descent |
///
/// ```
/// use twostage_models::{IoData, Prior};
/// use twostage_refine::{RefineError, RefineStarts, Refinement, ResidualModel};
/// # struct ConstantMean(Prior);
/// # impl ResidualModel for ConstantMean {
/// #     type Error = RefineError;
/// #     fn prior(&self) -> &Prior { &self.0 }
/// #     fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
/// #         for (r, y) in r.iter_mut().zip(record.output(0)) { *r = y - theta[0]; }
/// #         Ok(())
/// #     }
/// # }
/// // A model whose loss is sum (y_k - theta)^2, as in ResidualModel's example.
/// let model = ConstantMean(Prior::uniform_box(&[0.0], &[1.0])?);
/// let record = IoData::siso(&[0.0; 4], &[0.2, 0.4, 0.5, 0.5])?;
/// let refinement = Refinement::new(model);
/// // The minimum is the sample mean, 0.4, and lies in the box 0.3 +- 0.2.
/// let found = refinement.refine(&record, &[0.3], &[0.2], RefineStarts::Centre)?;
/// assert!((found.theta[0] - 0.4).abs() < 1e-6);
/// // Confined to 0.1 +- 0.2 the search stops at the box's face, 0.3.
/// let capped = refinement.refine(&record, &[0.1], &[0.2], RefineStarts::Centre)?;
/// assert!((capped.theta[0] - 0.3).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct Refinement<M> {
    model: M,
    max_iterations: usize,
}

impl<M: ResidualModel> Refinement<M> {
    /// Searches of `model`'s loss, 50 iterations per descent.
    pub fn new(model: M) -> Self {
        Self {
            model,
            max_iterations: 50,
        }
    }

    /// Iterations per descent.
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self
    }

    /// Iterations per descent.
    pub(crate) fn iterations(&self) -> usize {
        self.max_iterations
    }

    /// The residual model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// One Levenberg-Marquardt descent in the prior box (central
    /// differences, steps clipped to the box) from `start`: a local search,
    /// for a start that is already near the answer.
    ///
    /// # Errors
    /// A bad record, or a start of the wrong length.
    pub fn descend(&self, record: &IoData, start: Vec<f64>) -> Result<Descent, M::Error> {
        let mut found = self.descents_from(record, vec![start])?;
        Ok(found.remove(0))
    }

    /// One descent in the prior box from each of `starts`, in the starts'
    /// order. The descents run in lockstep: each round's points of all of
    /// them go to the model as one batch
    /// ([`ResidualModel::residuals_batch`]); each descent is still a
    /// function of its start alone, the same whatever the thread count.
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
    /// let fit = Refinement::new(ConstantMean(Prior::uniform_box(&[0.0], &[1.0])?));
    /// let record = IoData::siso(&[0.0; 4], &[0.2, 0.4, 0.5, 0.5])?;
    /// let descents = fit.descents_from(&record, vec![vec![0.1], vec![0.9]])?;
    /// // Both find the sample mean, each from its own start.
    /// assert_eq!(descents[1].start, [0.9]);
    /// assert!(descents.iter().all(|d| (d.theta[0] - 0.4).abs() < 1e-6));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// The first start (in order) whose descent fails.
    pub fn descents_from(
        &self,
        record: &IoData,
        starts: Vec<Vec<f64>>,
    ) -> Result<Vec<Descent>, M::Error> {
        let q = self.model.prior().dim();
        let jobs = starts
            .into_iter()
            .map(|start| DescentJob {
                record,
                start,
                lo: vec![0.0; q],
                hi: vec![1.0; q],
                group: 0,
                screen: None,
            })
            .collect();
        lockstep::descend_together(&self.model, self.max_iterations, jobs)
            .into_iter()
            .collect()
    }

    /// [`Refinement::descents_from`] for many records at once: every
    /// record's descents run in one lockstep, so a model that evaluates a
    /// batch of points at the price of one (a vectorized simulator, a
    /// source of several cores) gets full batches across the records. One
    /// result per record, in order, each the descents of its starts or the
    /// first of them that failed; a record's failure leaves the others'.
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
    /// let fit = Refinement::new(ConstantMean(Prior::uniform_box(&[0.0], &[1.0])?));
    /// let a = IoData::siso(&[0.0; 2], &[0.2, 0.4])?;
    /// let b = IoData::siso(&[0.0; 2], &[0.7, 0.9])?;
    /// let both = fit.descents_of_records(vec![(&a, vec![vec![0.5]]), (&b, vec![vec![0.5], vec![0.1]])]);
    /// assert!((both[0].as_ref().unwrap()[0].theta[0] - 0.3).abs() < 1e-6);
    /// assert_eq!(both[1].as_ref().unwrap().len(), 2);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn descents_of_records(
        &self,
        records: Vec<(&IoData, Vec<Vec<f64>>)>,
    ) -> Vec<Result<Vec<Descent>, M::Error>> {
        let (jobs, counts) = lockstep::record_jobs(records, self.model.prior().dim(), None);
        let mut results =
            lockstep::descend_together(&self.model, self.max_iterations, jobs).into_iter();
        counts
            .into_iter()
            .map(|count| results.by_ref().take(count).collect())
            .collect()
    }

    /// A local refinement of `start` (a TS estimate, say): descents
    /// confined to the box `start +- radius` (within the prior), keeping the
    /// lowest loss. The loss of an oscillating model has many basins; a good
    /// start lies in or next to the right one, and the confinement keeps the
    /// first Gauss-Newton steps from jumping out of the neighbourhood.
    /// [`RefineStarts::CentreAndAxes`] adds descents from `start +- radius/2`
    /// along each axis (each in its own part of the box), which finds the
    /// lowest basin of the box far more often, for 1 + 2q times the cost.
    ///
    /// # Errors
    /// A bad record, `start` or `radius` of the wrong length, a negative or
    /// NaN radius.
    pub fn refine(
        &self,
        record: &IoData,
        start: &[f64],
        radius: &[f64],
        starts: RefineStarts,
    ) -> Result<Descent, M::Error> {
        let prior = self.model.prior();
        let q = prior.dim();
        check_neighbourhood(q, start, radius)?;
        // The box in unit coordinates (within the prior's), and a start
        // confined to a sub-box.
        let unit = |theta: Vec<f64>| -> Vec<f64> {
            lockstep::to_unit(prior, &theta)
                .into_iter()
                .map(|s| s.clamp(0.0, 1.0))
                .collect()
        };
        let shifted = |side: f64| {
            start
                .iter()
                .zip(radius)
                .map(|(s, r)| s + side * r)
                .collect()
        };
        let (lo, hi) = (unit(shifted(-1.0)), unit(shifted(1.0)));
        let centre = unit(start.to_vec());
        let mut jobs = vec![DescentJob {
            record,
            start: start.to_vec(),
            lo: lo.clone(),
            hi: hi.clone(),
            group: 0,
            screen: None,
        }];
        if starts == RefineStarts::CentreAndAxes {
            for j in 0..q {
                for side in [-1.0, 1.0] {
                    let mut from = start.to_vec();
                    from[j] += side * 0.5 * radius[j];
                    // Its own half of the box along axis j.
                    let (mut l, mut h) = (lo.clone(), hi.clone());
                    let middle = centre[j];
                    if side < 0.0 {
                        h[j] = middle;
                    } else {
                        l[j] = middle;
                    }
                    jobs.push(DescentJob {
                        record,
                        start: from,
                        lo: l,
                        hi: h,
                        group: 0,
                        screen: None,
                    });
                }
            }
        }
        // The lowest loss; the first of equals, in the order of the starts.
        let mut best: Option<Descent> = None;
        for descent in lockstep::descend_together(&self.model, self.max_iterations, jobs) {
            let descent = descent?;
            if best.as_ref().is_none_or(|b| descent.loss < b.loss) {
                best = Some(descent);
            }
        }
        best.ok_or_else(|| {
            Error::Numerical {
                what: "a refinement without a descent".into(),
            }
            .into()
        })
    }

    /// The posterior mean over the box `centre +- radius` (within the
    /// prior), treating the loss as a Gaussian negative log-likelihood:
    /// `p(theta | D) ~ exp(-(L(theta) - L_min) / (2 s^2))` with the residual
    /// variance `s^2 = L_min / n` estimated from the best grid point, and the
    /// uniform prior. It is evaluated on a tensor grid of `points` per axis
    /// (`points^q` evaluations of the loss), so it suits few parameters.
    ///
    /// Where a multi-modal loss makes the minimizer jump between basins (the
    /// benchmark's sin(50 theta^2)), the posterior mean averages them as the
    /// Bayes-optimal estimate does: with a TS estimate as centre it comes
    /// close to the global posterior mean at a fraction of its cost.
    ///
    /// A posterior narrower than the grid's spacing lands on one point: its
    /// sd is reported at the grid's resolution, never below.
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
    /// let fit = Refinement::new(ConstantMean(Prior::uniform_box(&[-1.0], &[1.0])?));
    /// // 2000 samples within 1e-4 of 0.3: a posterior far narrower than a
    /// // grid of 0.1 over [0, 0.6].
    /// let y: Vec<f64> = (0..2000).map(|k| 0.3 + 1e-4 * ((k % 3) as f64 - 1.0)).collect();
    /// let record = IoData::siso(&vec![0.0; 2000], &y)?;
    /// let posterior = fit.local_posterior(&record, &[0.3], &[0.3], 7)?;
    /// assert!((posterior.mean[0] - 0.3).abs() < 1e-9);
    /// assert!((posterior.sd[0] - 0.1 / 12f64.sqrt()).abs() < 1e-12);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// A bad record, `centre` or `radius` of the wrong length, a negative or
    /// NaN radius, fewer than 2 points per axis or more than 2^20 in all, a
    /// loss that is nowhere finite on the grid.
    pub fn local_posterior(
        &self,
        record: &IoData,
        centre: &[f64],
        radius: &[f64],
        points: usize,
    ) -> Result<LocalPosterior, M::Error> {
        let prior = self.model.prior();
        let q = prior.dim();
        check_neighbourhood(q, centre, radius)?;
        let total = Some(points)
            .filter(|p| *p >= 2)
            .and_then(|p| p.checked_pow(q as u32))
            .filter(|t| *t <= 1 << 20)
            .ok_or_else(|| {
                Error::InvalidSetting(InvalidSetting {
                    name: "points per axis",
                    value: points.to_string(),
                    reason: format!("at least 2, and at most 2^20 grid points in all ({q} axes)"),
                })
            })?;
        let axes: Vec<Vec<f64>> = (0..q)
            .map(|j| {
                let lo = (centre[j] - radius[j]).max(prior.lower()[j]);
                let hi = (centre[j] + radius[j]).min(prior.upper()[j]);
                (0..points)
                    .map(|i| lo + (hi - lo) * i as f64 / (points - 1) as f64)
                    .collect()
            })
            .collect();
        let n = self.model.n_residuals(record);
        let mut residuals = vec![0.0; n];
        let mut theta = vec![0.0; q];
        let mut grid = Vec::with_capacity(total);
        for index in 0..total {
            let mut rest = index;
            for (t, axis) in theta.iter_mut().zip(&axes) {
                *t = axis[rest % points];
                rest /= points;
            }
            self.model.residuals(&theta, record, &mut residuals)?;
            let loss: f64 = residuals.iter().map(|r| r * r).sum();
            grid.push((theta.clone(), loss));
        }
        let best = grid.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
        if !best.is_finite() {
            return Err(Error::Numerical {
                what: format!(
                    "the loss is not finite anywhere on the local grid around {centre:?}: \
                     the model cannot predict this record there"
                ),
            }
            .into());
        }
        let variance = (best / n.max(1) as f64).max(f64::MIN_POSITIVE);
        let mut moments = WeightedMoments::new(q);
        for (t, loss) in &grid {
            moments.add((-(loss - best) / (2.0 * variance)).exp(), t);
        }
        let (mean, sd) = moments.mean_and_sd();
        // A posterior narrower than the grid resolves to one point: its sd
        // is then not known below the spacing, and reported at a uniform
        // cell's (spacing / sqrt 12), never as zero.
        let sd = sd
            .iter()
            .zip(&axes)
            .map(|(s, axis)| {
                let spacing = axis.get(1).zip(axis.first()).map_or(0.0, |(b, a)| b - a);
                s.max(spacing / 12f64.sqrt())
            })
            .collect();
        Ok(LocalPosterior {
            mean,
            sd,
            correlation: moments.correlation(),
            evaluations: total,
        })
    }
}

/// A centre and a radius that fit `q` parameters, with radii >= 0.
fn check_neighbourhood(q: usize, centre: &[f64], radius: &[f64]) -> Result<(), Error> {
    for (what, v) in [("the centre", centre), ("the radius", radius)] {
        if v.len() != q {
            return Err(Error::Length {
                what,
                found: v.len(),
                expected: q,
            });
        }
    }
    if let Some(r) = radius.iter().find(|r| r.is_nan() || **r < 0.0) {
        return Err(Error::InvalidSetting(InvalidSetting {
            name: "radius",
            value: r.to_string(),
            reason: "every radius >= 0".into(),
        }));
    }
    Ok(())
}
