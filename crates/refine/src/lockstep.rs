//! Many Levenberg-Marquardt descents run in lockstep: each round gathers
//! what every descent needs (its start, the forward-difference points of
//! its Jacobian, its trial steps) and hands them to the model in one
//! batch, so that a simulator behind a process is asked once per round for
//! all starts and records, not once per point. Each descent's arithmetic
//! is that of a descent run alone: the batching changes the number of
//! requests, never the result.

use twostage_fit::{
    Damping, ForwardDifferences, LevenbergMarquardt, LmRun, Need, TerminationReason,
};
use twostage_models::{IoData, Prior};

use crate::error::RefineError as Error;
use crate::residual::{Descent, ResidualModel};

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
    /// is screened out as its job's `screen` says.
    Join(f64),
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

/// A finished descent and, where it stopped beside another, which.
pub(crate) type Ended<E> = (Result<Descent, E>, Option<usize>);

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
        .map(|(descent, _)| descent)
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
                    Error::InvalidSetting {
                        name: "iterations per descent",
                        value: "0".into(),
                        reason: "at least 1".into(),
                    }
                    .into(),
                );
            }
            let run = Box::new(solver.run(to_unit(prior, &job.start), trials));
            Slot::Running {
                job,
                run,
                differences: None,
                joined: None,
            }
        })
        .collect();
    // The differences never step outside the prior box, where the model is
    // not defined.
    let (zeros, ones) = (vec![0.0; q], vec![1.0; q]);
    let mut screened = false;
    loop {
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
            } = &mut slots[d]
            else {
                continue;
            };
            if let Some(other) = met {
                run.abandon(TerminationReason::Joined);
                *joined = Some(other);
            } else if observing {
                run.proceed(false);
            }
            let before = points.len();
            match run.need() {
                Need::Evaluations => {
                    for point in run.evaluations_mut() {
                        for ((v, lo), hi) in point.x.iter_mut().zip(&job.lo).zip(&job.hi) {
                            *v = v.clamp(*lo, *hi);
                        }
                        points.push(to_theta(prior, &point.x));
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
                None => run.evaluated(),
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
            Slot::Failed(e) => (Err(e), None),
            Slot::Running {
                job, run, joined, ..
            } => {
                let found = run.finish();
                let descent = Descent {
                    start: job.start,
                    theta: to_theta(prior, &found.x),
                    loss: found.cost,
                    iterations: found.iterations,
                    stop: found.reason,
                };
                (Ok(descent), joined)
            }
        })
        .collect()
}
