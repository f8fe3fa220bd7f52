//! Many Levenberg-Marquardt descents run in lockstep: each round gathers
//! what every descent needs (its start, the forward-difference points of
//! its Jacobian, its trial steps) and hands them to the model in one
//! batch, so that a simulator behind a process is asked once per round for
//! all starts and records, not once per point. Each descent's arithmetic
//! is that of a descent run alone: the batching changes the number of
//! requests, never the result.

use crate::InvalidSetting;
use twostage_fit::{
    Damping, ForwardDifferences, LevenbergMarquardt, LmRun, Need, TerminationReason,
};
use twostage_models::{IoData, Prior};

use crate::error::RefineError as Error;
use crate::residual::{Descent, Evaluated, ResidualModel};

/// One descent to run: a record, a start (parameter values) and the box of
/// unit-box coordinates `[lo, hi]` its iterates stay in.
pub(crate) struct DescentJob<'a> {
    pub(crate) record: &'a IoData,
    pub(crate) start: Vec<f64>,
    pub(crate) lo: Vec<f64>,
    pub(crate) hi: Vec<f64>,
    /// The search the descent belongs to (one per record): descents join
    /// only descents of their own search.
    pub(crate) group: usize,
    /// With [`Meeting::Join`]: a start that has a lower start of its
    /// search within this distance (every unit-box coordinate) is not
    /// descended from at all (multi-level single linkage: its descent
    /// would most likely end where the lower one's does).
    pub(crate) screen: Option<f64>,
}

/// Descents over the whole unit box, one search per record in order, and
/// how many starts each record has. With `screen_share`, each start is
/// screened within that share of the side of its record's share of the
/// unit box (a cube of side `(1/n)^(1/q)` for `n` starts): a record's
/// descents are the same whatever the records beside it.
pub(crate) fn record_jobs<'a>(
    records: Vec<(&'a IoData, Vec<Vec<f64>>)>,
    q: usize,
    screen_share: Option<f64>,
) -> (Vec<DescentJob<'a>>, Vec<usize>) {
    let counts: Vec<usize> = records.iter().map(|(_, starts)| starts.len()).collect();
    let jobs = records
        .into_iter()
        .enumerate()
        .flat_map(|(group, (record, starts))| {
            let n = starts.len().max(1) as f64;
            let screen = screen_share.map(|share| share * (1.0 / n).powf(1.0 / q.max(1) as f64));
            starts.into_iter().map(move |start| DescentJob {
                record,
                start,
                lo: vec![0.0; q],
                hi: vec![1.0; q],
                group,
                screen,
            })
        })
        .collect();
    (jobs, counts)
}

/// How descents of one search that meet are treated: see
/// [`descend_together`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Meeting {
    /// Every descent runs to its own end.
    Apart,
    /// A descent whose accepted point comes within this distance (largest
    /// unit-box coordinate) of another's of its search standing at no
    /// higher cost stops there ([`TerminationReason::Joined`]); a start
    /// is screened out as its job's `screen` says; a descent that is
    /// outpaced ([`Outpacing`]) stops too.
    Join(f64),
}

/// When a descent of a search stops because it will not catch up with
/// the search's best ([`TerminationReason::Outpaced`]): after `iterations`
/// accepted steps its loss stands above `loss_over_best` times the lowest
/// loss any descent of its search stands at, and it did not fall by a
/// factor `progress` over its last `iterations` steps. A search's first
/// descent (from the estimate) is never outpaced: the search is never
/// worse than a refinement from the estimate alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Outpacing {
    pub(crate) loss_over_best: f64,
    pub(crate) iterations: usize,
    pub(crate) progress: f64,
}

impl Outpacing {
    /// Whether a descent whose accepted losses so far are `losses` (oldest
    /// first) is outpaced by a search whose best stands at `best`.
    fn outpaced(&self, losses: &[f64], best: f64) -> bool {
        let Some(&now) = losses.last() else {
            return false;
        };
        losses.len() > self.iterations
            && now > self.loss_over_best * best
            && losses[losses.len() - 1 - self.iterations] < self.progress * now
    }
}

/// The solver every refinement descent uses. Marquardt's scaling: the
/// parameters' sensitivities differ by orders of magnitude (the car's pK1
/// and pK2).
pub(crate) fn solver(max_iterations: usize) -> LevenbergMarquardt {
    LevenbergMarquardt::new()
        .max_iterations(max_iterations)
        .tolerance(1e-10)
        .damping(Damping::Diagonal { floor: 1e-12 })
        .initial_damping(1e-3)
        .max_damping(1e12f64.next_down())
}

/// Unit-box coordinates to parameter values.
pub(crate) fn to_theta(prior: &Prior, unit: &[f64]) -> Vec<f64> {
    unit.iter()
        .zip(prior.lower().iter().zip(prior.upper()))
        .map(|(si, (lo, hi))| lo + si * (hi - lo))
        .collect()
}

/// Parameter values to unit-box coordinates.
pub(crate) fn to_unit(prior: &Prior, theta: &[f64]) -> Vec<f64> {
    theta
        .iter()
        .zip(prior.lower().iter().zip(prior.upper()))
        .map(|(t, (lo, hi))| (t - lo) / (hi - lo))
        .collect()
}

/// A descent under way, or the error that ended it before it began.
enum Slot<'a, E> {
    Running {
        job: DescentJob<'a>,
        run: Box<LmRun>,
        /// The Jacobian's differences while their points are out.
        differences: Option<ForwardDifferences>,
        /// The descent it stopped beside, when it joined one.
        joined: Option<usize>,
        /// Its accepted losses, oldest first, its start's the first.
        losses: Vec<f64>,
        /// Its start and the residuals there, kept for a search's first
        /// descent.
        first_start: Option<Box<Evaluated>>,
    },
    Failed(E),
}

/// The descent of `slots` (not `d`, not itself joined, of the same group)
/// that descent `d`, at its accepted point (or its start), joins: within
/// `tolerance` of it in every coordinate, at no higher cost (the earlier
/// of equals). `None` when none is.
fn meets<E>(slots: &[Slot<'_, E>], d: usize, tolerance: f64) -> Option<usize> {
    let Slot::Running { job, run, .. } = &slots[d] else {
        return None;
    };
    if !run.started() {
        return None;
    }
    let here = run.iterate();
    slots.iter().enumerate().find_map(|(e, other)| {
        let Slot::Running {
            job: other_job,
            run: other_run,
            joined: None,
            ..
        } = other
        else {
            return None;
        };
        if e == d || other_job.group != job.group || !other_run.started() {
            return None;
        }
        let there = other_run.iterate();
        let near = here
            .x
            .iter()
            .zip(there.x)
            .all(|(a, b)| (a - b).abs() <= tolerance);
        let lower = there.cost.total_cmp(&here.cost).then(e.cmp(&d)).is_lt();
        (near && lower).then_some(e)
    })
}

/// The outpacing of every search: ten times the best's loss (a fit three
/// times worse in RMS), and not halving it in five steps.
pub(crate) const OUTPACING: Outpacing = Outpacing {
    loss_over_best: 10.0,
    iterations: 5,
    progress: 2.0,
};

/// The lowest loss a started descent of each group stands at (infinite
/// for a group none of whose descents has started).
fn lowest_by_group<E>(slots: &[Slot<'_, E>]) -> Vec<f64> {
    let mut best: Vec<f64> = Vec::new();
    for slot in slots {
        if let Slot::Running { job, run, .. } = slot
            && run.started()
        {
            if best.len() <= job.group {
                best.resize(job.group + 1, f64::INFINITY);
            }
            best[job.group] = best[job.group].min(run.iterate().cost);
        }
    }
    best
}

/// A finished descent, where it stopped beside another which, and (for a
/// search, [`Meeting::Join`]) the residuals at its end and, for a
/// search's first descent, at its start: what a check of those points
/// reads instead of simulating them again.
pub(crate) struct Ended<E> {
    pub(crate) descent: Result<Descent, E>,
    pub(crate) joined: Option<usize>,
    pub(crate) first_start: Option<Evaluated>,
    pub(crate) end_residuals: Vec<f64>,
}

/// Run `jobs` together, one result per job in order. A start the model
/// cannot evaluate fails its own descent only; a trial step it cannot
/// evaluate is refused (the descent goes on with more damping); a failed
/// Jacobian point ends its descent at its last accepted point
/// ([`TerminationReason::EvaluationFailed`]).
///
/// With [`Meeting::Join`], a descent that comes where another of its
/// search already stands at no higher cost stops there: the rounds are the
/// same whatever the thread count, so which descents join is too.
pub(crate) fn descend_together<M: ResidualModel>(
    model: &M,
    max_iterations: usize,
    jobs: Vec<DescentJob<'_>>,
) -> Vec<Result<Descent, M::Error>> {
    descend_meeting(model, max_iterations, jobs, Meeting::Apart)
        .into_iter()
        .map(|ended| ended.descent)
        .collect()
}

/// [`descend_together`], descents meeting as `meeting` says; each result
/// with the descent it joined, if any.
pub(crate) fn descend_meeting<M: ResidualModel>(
    model: &M,
    max_iterations: usize,
    jobs: Vec<DescentJob<'_>>,
    meeting: Meeting,
) -> Vec<Ended<M::Error>> {
    let prior = model.prior();
    let q = prior.dim();
    let solver = solver(max_iterations);
    let trials = model.trials_at_once();
    let mut slots: Vec<Slot<'_, M::Error>> = jobs
        .into_iter()
        .map(|job| {
            if job.start.len() != q {
                return Slot::Failed(
                    Error::Length {
                        what: "the start",
                        found: job.start.len(),
                        expected: q,
                    }
                    .into(),
                );
            }
            if max_iterations == 0 {
                return Slot::Failed(
                    Error::InvalidSetting(InvalidSetting {
                        name: "iterations per descent",
                        value: "0".into(),
                        reason: "at least 1".into(),
                    })
                    .into(),
                );
            }
            let run = Box::new(solver.run(to_unit(prior, &job.start), trials));
            Slot::Running {
                job,
                run,
                differences: None,
                joined: None,
                losses: Vec::new(),
                first_start: None,
            }
        })
        .collect();
    let search = matches!(meeting, Meeting::Join(_));
    // Each search's first descent, which is never outpaced.
    let firsts: Vec<usize> = (0..slots.len())
        .filter(|&d| {
            let group = |d: usize| match &slots[d] {
                Slot::Running { job, .. } => Some(job.group),
                Slot::Failed(_) => None,
            };
            d == 0 || group(d) != group(d - 1)
        })
        .collect();
    // The differences never step outside the prior box, where the model is
    // not defined.
    let (zeros, ones) = (vec![0.0; q], vec![1.0; q]);
    let mut screened = false;
    loop {
        // Each search's lowest loss as the round begins: every descent
        // of the round is judged against the same.
        let best = lowest_by_group(&slots);
        let mut points: Vec<Vec<f64>> = Vec::new();
        let mut records: Vec<&IoData> = Vec::new();
        // Each asking descent and how many of the points are its own, in order.
        let mut askers: Vec<(usize, usize)> = Vec::new();
        for d in 0..slots.len() {
            let observing =
                matches!(&slots[d], Slot::Running { run, .. } if run.need() == Need::Observe);
            let met = match meeting {
                Meeting::Join(distance) if observing => meets(&slots, d, distance),
                _ => None,
            };
            let Slot::Running {
                job,
                run,
                differences,
                joined,
                losses,
                ..
            } = &mut slots[d]
            else {
                continue;
            };
            if observing {
                losses.push(run.iterate().cost);
            }
            let outpaced = match meeting {
                Meeting::Join(_) if observing && !firsts.contains(&d) => best
                    .get(job.group)
                    .is_some_and(|&b| OUTPACING.outpaced(losses, b)),
                _ => false,
            };
            if let Some(other) = met {
                run.abandon(TerminationReason::Joined);
                *joined = Some(other);
            } else if outpaced {
                run.abandon(TerminationReason::Outpaced);
            } else if observing {
                run.proceed(false);
            }
            let before = points.len();
            match run.need() {
                Need::Evaluations => {
                    let starting = !run.started();
                    for point in run.evaluations_mut() {
                        let mut clamped = false;
                        for ((v, lo), hi) in point.x.iter_mut().zip(&job.lo).zip(&job.hi) {
                            clamped |= *v < *lo || *v > *hi;
                            *v = v.clamp(*lo, *hi);
                        }
                        // A start inside the box is evaluated at its own
                        // values, not their round trip through the unit
                        // box: its residuals then are those at the start.
                        points.push(if starting && !clamped {
                            job.start.clone()
                        } else {
                            to_theta(prior, &point.x)
                        });
                    }
                }
                Need::Model => {
                    // Forward: q points a Jacobian, not 2q (the residuals
                    // at the point are the descent's own).
                    let (forward, at) =
                        ForwardDifferences::at(run.model_mut().x, Some((&zeros, &ones)));
                    points.extend(at.iter().map(|point| to_theta(prior, point)));
                    *differences = Some(forward);
                }
                Need::Observe | Need::Done => {}
            }
            if points.len() > before {
                records.resize(points.len(), job.record);
                askers.push((d, points.len() - before));
            }
        }
        if points.is_empty() {
            break;
        }
        let pairs: Vec<(&[f64], &IoData)> = points
            .iter()
            .map(Vec::as_slice)
            .zip(records.iter().copied())
            .collect();
        let mut values = vec![Vec::new(); points.len()];
        let results = model.residuals_batch(&pairs, &mut values);
        let mut answers = results.into_iter().zip(values);
        for (d, count) in askers {
            let mine: Vec<_> = answers.by_ref().take(count).collect();
            let Slot::Running {
                run, differences, ..
            } = &mut slots[d]
            else {
                continue;
            };
            if let Some(forward) = differences.take() {
                if mine.iter().any(|(result, _)| result.is_err()) {
                    run.abandon(TerminationReason::EvaluationFailed);
                } else {
                    let columns: Vec<Vec<f64>> = mine.into_iter().map(|(_, v)| v).collect();
                    let m = run.model_mut();
                    forward.products(&columns, m.residuals, m.jtj, m.jtr);
                    run.modelled();
                }
                continue;
            }
            let starting = !run.started();
            let mut start_failed = None;
            for ((result, value), point) in mine.into_iter().zip(run.evaluations_mut()) {
                match result {
                    Ok(()) => {
                        point.cost = value.iter().map(|v| v * v).sum();
                        point.residuals = value;
                    }
                    Err(e) if starting => start_failed = Some(e),
                    // A trial the model cannot evaluate is a refused step.
                    Err(_) => point.cost = f64::INFINITY,
                }
            }
            match start_failed {
                Some(e) => slots[d] = Slot::Failed(e),
                None => {
                    run.evaluated();
                    let keep = starting && run.started() && search && firsts.contains(&d);
                    if keep
                        && let Slot::Running {
                            job,
                            run,
                            first_start,
                            ..
                        } = &mut slots[d]
                    {
                        // The point evaluated: the start itself inside the box.
                        let x = run.iterate().x;
                        let inside = to_unit(prior, &job.start) == x;
                        *first_start = Some(Box::new(Evaluated {
                            theta: if inside {
                                job.start.clone()
                            } else {
                                to_theta(prior, x)
                            },
                            residuals: run.model_mut().residuals.to_vec(),
                        }));
                    }
                }
            }
        }
        // Every start is evaluated in the first round: screen them once,
        // all against the same costs, before any descends.
        if matches!(meeting, Meeting::Join(_)) && !screened {
            screened = true;
            let out: Vec<(usize, usize)> = (0..slots.len())
                .filter_map(|d| {
                    let Slot::Running { job, .. } = &slots[d] else {
                        return None;
                    };
                    meets(&slots, d, job.screen?).map(|e| (d, e))
                })
                .collect();
            for (d, e) in out {
                if let Slot::Running { run, joined, .. } = &mut slots[d] {
                    run.abandon(TerminationReason::Joined);
                    *joined = Some(e);
                }
            }
        }
    }
    slots
        .into_iter()
        .map(|slot| match slot {
            Slot::Failed(e) => Ended {
                descent: Err(e),
                joined: None,
                first_start: None,
                end_residuals: Vec::new(),
            },
            Slot::Running {
                job,
                mut run,
                joined,
                first_start,
                ..
            } => {
                let end_residuals = if search {
                    run.model_mut().residuals.to_vec()
                } else {
                    Vec::new()
                };
                let found = run.finish();
                let descent = Descent {
                    start: job.start,
                    theta: to_theta(prior, &found.x),
                    loss: found.cost,
                    iterations: found.iterations,
                    stop: found.reason,
                };
                Ended {
                    descent: Ok(descent),
                    joined,
                    first_start: first_start.map(|b| *b),
                    end_residuals,
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule on hand-made loss paths against a best of 1.
    #[test]
    fn a_slow_descent_far_above_the_best_is_outpaced() {
        let rule = OUTPACING;
        // Six accepted losses, from 30 to 20: not halved in five steps,
        // above ten times the best.
        assert!(rule.outpaced(&[30.0, 28.0, 26.0, 24.0, 22.0, 20.0], 1.0));
        // The same path five steps long: too soon to tell.
        assert!(!rule.outpaced(&[28.0, 26.0, 24.0, 22.0, 20.0], 1.0));
        // Halved in five steps: still descending fast enough.
        assert!(!rule.outpaced(&[41.0, 35.0, 30.0, 26.0, 23.0, 20.0], 1.0));
        // Slow, but within ten times the best: it may be a near rival.
        assert!(!rule.outpaced(&[9.9, 9.8, 9.7, 9.6, 9.5, 9.5], 1.0));
        // Only the last five steps count: a fast start does not save it.
        assert!(rule.outpaced(&[1e6, 30.0, 28.0, 26.0, 24.0, 22.0, 20.0], 1.0));
    }
}
