//! The best fit a model reaches on a record anywhere in its prior, not
//! only beside an estimate: descents from the estimate, from the corners
//! of its interval and from points spread over the prior's mass, in one
//! lockstep, each stopping where it meets another or once it stands far
//! above the best and makes little progress. The check judges an
//! estimate against it, and the output-error refinement is its best
//! descent, so that one search serves both.

use crate::InvalidSetting;
use twostage_models::{IoData, Prior, Sampling};

use crate::RefineError;
use crate::lockstep::{self, Meeting};
use crate::refinement::{Descent, Refinement, ResidualModel};
use crate::residual::Evaluated;
use twostage_fit::TerminationReason;

/// Descents whose accepted points come this close (in every coordinate of
/// the prior's unit box) meet: the one standing higher stops.
pub const JOIN_DISTANCE: f64 = 1e-2;

/// A start is not descended from when a lower start of its search lies
/// within this share of the side of its cube of the unit box (a cube of
/// side `(1/n)^(1/q)` for `n` starts): multi-level single linkage (Rinnooy
/// Kan and Timmer, 1987, Math. Programming 39), where such a start's
/// descent most likely ends where the lower one's does.
pub const SCREEN_SHARE: f64 = 0.5;

/// Ends of descents this close (in every coordinate of the prior's unit
/// box) are one optimum.
pub const SAME_OPTIMUM: f64 = 1e-2;

/// Where a best-fit search starts, besides the estimate: the corners of
/// its interval, and `from_prior` points of a low-discrepancy design of
/// the prior (Sobol, shifted by `seed`; a Latin hypercube beyond Sobol's
/// dimensions), so that a basin the estimate is not in is still reached.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `from_prior` | [`SearchStarts::default_from_prior`]`(q)`, `2 q + 2` | >= 0 (0: the estimate's neighbourhood only) |
/// | `seed` | the check's seed | any |
///
/// ```
/// use twostage_models::Prior;
/// use twostage_refine::SearchStarts;
/// let prior = Prior::uniform_box(&[0.0, 0.0], &[1.0, 10.0])?;
/// let starts = SearchStarts { from_prior: 6, seed: 0 };
/// let all = starts.starts(&prior, &[0.5, 5.0], Some(&[0.1, 1.0]))?;
/// // The estimate, two corners of half its interval, six from the prior.
/// assert_eq!(all.len(), 9);
/// assert_eq!(all[0], [0.5, 5.0]);
/// assert_eq!(all[1], [0.55, 4.5]);
/// assert!(all[3..].iter().all(|s| prior.contains(s)));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SearchStarts {
    /// Starts drawn over the prior's mass.
    pub from_prior: usize,
    /// The seed of their design.
    pub seed: u64,
}

impl SearchStarts {
    /// The starts from the prior a search of `q` parameters takes by
    /// default: two per parameter and two more.
    pub fn default_from_prior(q: usize) -> usize {
        2 * q + 2
    }

    /// The starts of a search around `estimate` (with its interval
    /// `half_widths`, where known): the estimate, the corners of
    /// [`spread_starts`], then the prior's.
    ///
    /// # Errors
    /// An estimate or half-widths of another length than the prior's.
    pub fn starts(
        &self,
        prior: &Prior,
        estimate: &[f64],
        half_widths: Option<&[f64]>,
    ) -> Result<Vec<Vec<f64>>, RefineError> {
        let q = prior.dim();
        for (what, found) in [
            ("the estimate", Some(estimate.len())),
            ("the half-widths", half_widths.map(<[f64]>::len)),
        ] {
            if let Some(found) = found.filter(|n| *n != q) {
                return Err(RefineError::Length {
                    what,
                    found,
                    expected: q,
                });
            }
        }
        let mut starts = match half_widths {
            Some(widths) => spread_starts(estimate, widths),
            None => vec![estimate.to_vec()],
        };
        if self.from_prior > 0 {
            let sampling = if q <= Prior::MAX_SOBOL_DIMENSION {
                Sampling::Sobol
            } else {
                Sampling::LatinHypercube
            };
            let design = prior
                .clone()
                .with_sampling(sampling)
                .design(self.from_prior, self.seed)
                .map_err(|source| RefineError::Simulation {
                    what: "the best-fit search's starts",
                    source,
                })?;
            for i in 0..self.from_prior {
                let mut theta = vec![0.0; q];
                design
                    .fill_theta(i, &mut theta)
                    .map_err(|source| RefineError::Simulation {
                        what: "the best-fit search's starts",
                        source,
                    })?;
                starts.push(theta);
            }
        }
        Ok(starts)
    }
}

/// Where a refinement starts around an estimate: the estimate, and two
/// corners of half its interval on either side (alternating signs across
/// the parameters), so that a start lies off each axis the estimate may
/// be wrong along. The descents are bounded by the prior, not the
/// interval: on a real record the model's best fit may lie outside an
/// interval calibrated on the model's own records.
///
/// ```
/// let starts = twostage_refine::spread_starts(&[1.0, 2.0], &[0.2, 0.4]);
/// assert_eq!(starts, [vec![1.0, 2.0], vec![1.1, 1.8], vec![0.9, 2.2]]);
/// ```
pub fn spread_starts(estimate: &[f64], half_widths: &[f64]) -> Vec<Vec<f64>> {
    let corner = |sign: f64| -> Vec<f64> {
        estimate
            .iter()
            .zip(half_widths)
            .enumerate()
            .map(|(j, (t, w))| {
                let alternate = if j % 2 == 0 { 1.0 } else { -1.0 };
                t + sign * alternate * 0.5 * w
            })
            .collect()
    };
    vec![estimate.to_vec(), corner(1.0), corner(-1.0)]
}

/// One optimum a best-fit search ended in.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// Where (the lowest end among the descents that reached it).
    pub theta: Vec<f64>,
    /// Its loss.
    pub loss: f64,
    /// How many descents ended there, or stopped on the way there.
    pub descents: usize,
}

/// What a best-fit search found on one record.
#[derive(Debug, Clone, PartialEq)]
pub struct BestFit {
    /// The lowest descent: its end is the best fit.
    pub best: Descent,
    /// The distinct optima the descents ended in, lowest loss first (a
    /// descent outpaced on its way is not counted: it ended on a slope).
    pub optima: Vec<Optimum>,
    /// The descents run.
    pub descents: usize,
    /// The first start (the estimate) with its residuals, where it was
    /// evaluated: a check of the estimate reads them instead of simulating
    /// it again.
    pub first_start: Option<Evaluated>,
    /// The residuals at the best fit, as its loss sums them.
    pub best_residuals: Vec<f64>,
}

impl BestFit {
    /// The loss of the second-best optimum over the best's (`None` with
    /// one optimum): near 1, the record does not tell two basins apart.
    pub fn runner_up_ratio(&self) -> Option<f64> {
        let second = self.optima.get(1)?;
        Some(if self.best.loss > 0.0 {
            second.loss / self.best.loss
        } else {
            f64::INFINITY
        })
    }
}

impl<M: ResidualModel> Refinement<M> {
    /// The best fit of each record from its `starts` (see
    /// [`SearchStarts::starts`]): every record's descents in one lockstep,
    /// a descent stopping where it meets another of its record standing
    /// no higher ([`JOIN_DISTANCE`]), or where it stands above ten times
    /// the search's lowest loss without halving its own in five steps
    /// ([`TerminationReason::Outpaced`]; never the descent from the first
    /// start); the ends grouped into optima
    /// ([`SAME_OPTIMUM`]). A start the model cannot evaluate leaves the
    /// others; a record whose every start fails gives the first failure.
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
    /// let found = fit.best_fits(vec![(&record, vec![vec![0.1], vec![0.9], vec![0.5]])]);
    /// let found = found[0].as_ref().unwrap();
    /// // One optimum, the sample mean, which all three descents reach.
    /// assert_eq!((found.optima.len(), found.optima[0].descents), (1, 3));
    /// assert!((found.best.theta[0] - 0.4).abs() < 1e-6 && found.runner_up_ratio().is_none());
    /// // A record without a start is refused, the others searched.
    /// let both = fit.best_fits(vec![(&record, vec![]), (&record, vec![vec![0.5]])]);
    /// assert!(both[0].is_err() && both[1].is_ok());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn best_fits(
        &self,
        searches: Vec<(&IoData, Vec<Vec<f64>>)>,
    ) -> Vec<Result<BestFit, M::Error>> {
        let prior = self.model().prior();
        let (jobs, counts) = lockstep::record_jobs(searches, prior.dim(), Some(SCREEN_SHARE));
        let mut ended = lockstep::descend_meeting(
            self.model(),
            self.iterations(),
            jobs,
            Meeting::Join(JOIN_DISTANCE),
        )
        .into_iter();
        let mut first = 0;
        counts
            .into_iter()
            .map(|count| {
                let mine: Vec<_> = ended.by_ref().take(count).collect();
                let found = summarize(prior, mine, first);
                first += count;
                found
            })
            .collect()
    }
}

/// One record's descents (`first` the index of its first among all, as
/// the joins name them) as its best fit and optima.
fn summarize<E: From<RefineError>>(
    prior: &Prior,
    ended: Vec<lockstep::Ended<E>>,
    first: usize,
) -> Result<BestFit, E> {
    let descents = ended.len();
    // Which descent each joined one stopped beside, followed to the one
    // that ran on (a descent joins only one that has not joined).
    let root = |mut d: usize| {
        while let Some(Some(other)) = ended.get(d).map(|e| e.joined) {
            d = other - first;
        }
        d
    };
    let roots: Vec<usize> = (0..descents).map(root).collect();
    let mut error = None;
    let mut ran_on: Vec<(usize, &Descent)> = Vec::new();
    for (d, e) in ended.iter().enumerate() {
        match &e.descent {
            // An outpaced descent stopped on a slope, not at an optimum.
            Ok(descent) if e.joined.is_none() && descent.stop != TerminationReason::Outpaced => {
                ran_on.push((d, descent));
            }
            Ok(_) => {}
            Err(_) if error.is_none() => error = Some(d),
            Err(_) => {}
        }
    }
    if ran_on.is_empty() {
        // Every start failed (a descent that joined another leads to one
        // that ran on), or there was none.
        return Err(match error.and_then(|d| ended.into_iter().nth(d)) {
            Some(lockstep::Ended {
                descent: Err(e), ..
            }) => e,
            _ => RefineError::InvalidSetting(InvalidSetting {
                name: "starts",
                value: "none".into(),
                reason: "a best-fit search needs at least one start".into(),
            })
            .into(),
        });
    }
    // Lowest loss first; the earlier start of equals.
    ran_on.sort_by(|a, b| a.1.loss.total_cmp(&b.1.loss).then(a.0.cmp(&b.0)));
    let mut optima: Vec<(Vec<f64>, Optimum)> = Vec::new();
    for (d, descent) in &ran_on {
        let unit = lockstep::to_unit(prior, &descent.theta);
        let joined = roots
            .iter()
            .enumerate()
            .filter(|(e, r)| **r == *d && e != d)
            .count();
        match optima.iter_mut().find(|(at, _)| {
            at.iter()
                .zip(&unit)
                .all(|(a, b)| (a - b).abs() <= SAME_OPTIMUM)
        }) {
            Some((_, optimum)) => optimum.descents += 1 + joined,
            None => optima.push((
                unit,
                Optimum {
                    theta: descent.theta.clone(),
                    loss: descent.loss,
                    descents: 1 + joined,
                },
            )),
        }
    }
    let (best_at, best) = (ran_on[0].0, ran_on[0].1.clone());
    let mut ended = ended;
    let first_start = ended.first_mut().and_then(|e| e.first_start.take());
    let best_residuals = std::mem::take(&mut ended[best_at].end_residuals);
    Ok(BestFit {
        best,
        optima: optima.into_iter().map(|(_, optimum)| optimum).collect(),
        descents,
        first_start,
        best_residuals,
    })
}
