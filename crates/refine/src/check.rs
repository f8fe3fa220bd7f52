//! Does the model, at an estimate, explain the record it came from? The
//! noise-free simulation on the record's own input, its fit to the
//! record, and how typical that misfit is of the model's own noisy
//! records at the estimate (`twostage estimate --check`).

use crate::InvalidSetting;
use rayon::prelude::*;
use std::ops::Range;
use twostage_models::{Conditions, IoData, Simulator, experiment_rng};

use crate::best_fit::{BestFit, SearchStarts};
use crate::improvement::ResponseSpan;
use crate::output_error::{response_from_output_errors, write_output_errors};
use crate::refinement::Refinement;
use crate::{OutputError, RefineError};

/// At or below this tail probability a record is not one the model makes
/// at its estimate (a 1% test: about one good record in a hundred is
/// flagged). It takes at least 99 of the model's own records to reach.
pub const EXPLAINED_LEVEL: f64 = 0.01;

/// An estimate is as good as the model gets when its output-error loss is
/// within this factor of the best fit the model reaches anywhere in its
/// prior (5% in RMS): on a record the model does not quite make (a real
/// plant), that is what can be asked of an estimate.
pub const NEAR_BEST_LOSS: f64 = 1.1;

/// The most runs of the model's own records a check ranks a record among
/// when its caller does not say (the command line's `--check-sims`, the
/// Python package's `sims`): the tail probability then resolves to 1/200,
/// half of [`EXPLAINED_LEVEL`].
pub const DEFAULT_CHECK_RUNS: usize = 199;

/// The check's noisy runs may stop once this many miss by at least as much
/// as the record: the tail probability is then known to about a third of
/// itself, and well above the level.
pub const STOP_EXCEEDANCES: usize = 10;

/// The counts at which the check's noisy runs may stop, ending at `noisy`.
fn block_ends(noisy: usize) -> Vec<usize> {
    let mut ends: Vec<usize> = [19, 39, 99, 199, 499, 999, 1999, 4999]
        .into_iter()
        .filter(|&end| end < noisy)
        .collect();
    ends.push(noisy);
    ends
}

/// How one record compares with the model's response at its estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordCheck {
    /// Per output: the RMS of record minus noise-free simulation.
    pub rms: Vec<f64>,
    /// Per output: the normalized fit, `100 (1 - |y - y_sim| / |y -
    /// mean(y)|)` percent, as system identification tools report it.
    pub fit_percent: Vec<f64>,
    /// The share of the model's own records at the estimate (noisy, on
    /// the same input) whose misfit is at least the record's: small means
    /// the record is not what the model makes at this estimate. Estimated
    /// from the runs made: all of them for a record near or below the 1%
    /// level, as few as 19 for one well above it.
    pub tail_probability: f64,
    /// The share of the model's own records at the estimate (the same
    /// runs) whose best fit would improve on the estimate at least as much
    /// as the record's best fit does: its output-error loss below the
    /// estimate's over the scoring window, to first order for the model's
    /// records (the share of their noise in the span of the model's
    /// response to small parameter changes). Small means the record's best
    /// fit beats the estimate by more than the model's noise explains.
    pub improvement_tail_probability: f64,
    /// The share of the model's own records at the estimate (the same
    /// runs) that miss the estimate's response by at least as much as the
    /// record misses its best fit's: small means the model does not make
    /// the record anywhere near its best fit (a model that is not exact
    /// for it), where a small [`Self::tail_probability`] alone may be a
    /// poor estimate's.
    pub best_fit_tail_probability: f64,
    /// How many of the model's own records were run.
    pub reference_runs: usize,
    /// The noise-free simulation, for plots.
    pub simulated: IoData,
    /// When the model gives every experiment the same input (so an
    /// estimator trained on it learned that input): where the record's
    /// input first differs from it, as (input signal, sample). `None`
    /// when it is the same, or when the model's inputs vary.
    pub input_differs_at: Option<(usize, usize)>,
    /// Whether the model gives every experiment the same input.
    pub input_shared: bool,
    /// The output-error loss at the estimate over the loss of the best fit
    /// the search reached from the estimate and from the prior (1 at the
    /// best fit; below 1 where the estimate fits better still).
    pub loss_ratio: f64,
    /// Per output, the normalized fit of that best fit.
    pub best_fit_percent: Vec<f64>,
    /// Where that best fit lies.
    pub best_theta: Vec<f64>,
    /// How many distinct optima the search's descents ended in.
    pub optima: usize,
    /// The second-best optimum's loss over the best's (`None` with one
    /// optimum).
    pub runner_up_ratio: Option<f64>,
}

impl RecordCheck {
    /// Whether the record is one the model makes at the estimate, by the
    /// model's own noise.
    pub fn model_consistent(&self) -> bool {
        self.tail_probability > EXPLAINED_LEVEL
    }

    /// Whether the record's best fit improves on the estimate no more than
    /// the model's own noise would ([`Self::improvement_tail_probability`]
    /// above the 1% level).
    pub fn as_good_as_best_fit(&self) -> bool {
        self.improvement_tail_probability > EXPLAINED_LEVEL
    }

    /// Whether the record is one the model makes at its best fit, by the
    /// model's own noise ([`Self::best_fit_tail_probability`] above the 1%
    /// level): the model is exact enough for the record.
    pub fn best_fit_consistent(&self) -> bool {
        self.best_fit_tail_probability > EXPLAINED_LEVEL
    }

    /// Whether the model explains the record at the estimate: where the
    /// model makes the record at its best fit, the best fit does no better
    /// than the model's noise allows ([`Self::as_good_as_best_fit`]);
    /// where it does not (a model that is not exact), the estimate fits
    /// the record within 5% in RMS of the best fit the search reached
    /// anywhere in the prior ([`NEAR_BEST_LOSS`]). An estimate that is not
    /// explained misses the record where the model need not: another
    /// input than training's, a poor estimate, an estimate in another
    /// basin than the best fit's.
    pub fn explained(&self) -> bool {
        if self.best_fit_consistent() {
            self.as_good_as_best_fit()
        } else {
            self.loss_ratio <= NEAR_BEST_LOSS
        }
    }
}

/// Where `record`'s inputs first differ from `shared`'s, as (signal,
/// sample), beyond rounding (1e-9 of the signal's largest magnitude).
fn first_difference(record: &IoData, shared: &IoData) -> Option<(usize, usize)> {
    (0..shared.n_inputs()).find_map(|j| {
        let (a, b) = (record.input(j), shared.input(j));
        let scale = 1e-9 * (1.0 + b.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        if a.len() != b.len() {
            return Some((j, a.len().min(b.len())));
        }
        a.iter()
            .zip(b)
            .position(|(x, y)| (x - y).abs() > scale)
            .map(|k| (j, k))
    })
}

/// How well `simulated` follows `measured` (one signal): the RMS of their
/// difference, and the normalized fit `100 (1 - |y - y_sim| / |y - mean
/// y|)` percent (NaN for a constant record) that system identification
/// tools report.
///
/// ```
/// let (rms, fit) = twostage_refine::output_fit(&[1.0, 3.0], &[1.0, 2.0]);
/// // |y - y_sim| = 1, |y - mean y| = sqrt(2).
/// assert_eq!(rms, 0.5f64.sqrt());
/// assert!((fit - 100.0 * (1.0 - 0.5f64.sqrt())).abs() < 1e-12);
/// ```
pub fn output_fit(measured: &[f64], simulated: &[f64]) -> (f64, f64) {
    let n = measured.len().max(1) as f64;
    let misfit: f64 = measured
        .iter()
        .zip(simulated)
        .map(|(y, s)| (y - s) * (y - s))
        .sum();
    let mean = measured.iter().sum::<f64>() / n;
    let spread: f64 = measured.iter().map(|v| (v - mean) * (v - mean)).sum();
    let fit = if spread > 0.0 {
        100.0 * (1.0 - (misfit / spread).sqrt())
    } else {
        f64::NAN
    };
    ((misfit / n).sqrt(), fit)
}

/// Mean square of `a - b` per output, over the samples of `window`.
fn mean_squares(a: &IoData, b: &IoData, window: Range<usize>) -> Vec<f64> {
    (0..a.n_outputs())
        .map(|j| {
            let (x, y) = (&a.output(j)[window.clone()], &b.output(j)[window.clone()]);
            x.iter().zip(y).map(|(p, q)| (p - q) * (p - q)).sum::<f64>() / x.len().max(1) as f64
        })
        .collect()
}

/// How a record is checked: see [`check_with`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CheckPlan {
    /// The most noisy runs of the model the record is ranked among.
    pub noisy: usize,
    /// The seed of their streams.
    pub seed: u64,
    /// Score from this sample on (the misfits, fits and the tail
    /// probability); the first samples of a transient are left out. The
    /// best fit is still fitted to the whole record.
    pub score_from: usize,
    /// Score up to this sample, not including it (`None`: to the record's
    /// end); a tail the model is not meant for is left out.
    pub score_to: Option<usize>,
    /// The best-fit search's starts drawn over the prior, besides the
    /// estimate ([`SearchStarts`]; 0 searches beside the estimate only).
    pub prior_starts: usize,
}

impl CheckPlan {
    /// The plan of `noisy` runs of streams `seed`, scored from the first
    /// sample, searching from [`SearchStarts::default_from_prior`] starts
    /// of a model of `q` parameters.
    pub fn new(noisy: usize, seed: u64, q: usize) -> Self {
        Self {
            noisy,
            seed,
            score_from: 0,
            score_to: None,
            prior_starts: SearchStarts::default_from_prior(q),
        }
    }

    /// The samples scored of a record of `n`: from
    /// [`score_from`](Self::score_from) up to [`score_to`](Self::score_to)
    /// or the end (empty where that is not inside the record).
    pub fn scored(&self, n: usize) -> Range<usize> {
        let to = self.score_to.unwrap_or(n).min(n);
        self.score_from.min(to)..to
    }

    /// The starts of its best-fit search beside an estimate.
    pub fn search(&self) -> SearchStarts {
        SearchStarts {
            from_prior: self.prior_starts,
            seed: self.seed,
        }
    }
}

/// [`check_record`] as `plan` says: its scoring window and its best-fit
/// search's starts.
///
/// ```
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// use twostage_refine::{CheckPlan, check_with};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.3], &mut experiment_rng(7, 0), &mut record)?;
/// let plan = CheckPlan { noisy: 99, seed: 1, score_from: 100, score_to: Some(900), prior_starts: 4 };
/// let check = check_with(&model, &record, &[0.3], plan)?;
/// assert!(check.explained());
/// // A window past the record, or empty, is named.
/// let past = CheckPlan { score_from: 1000, score_to: None, ..plan };
/// assert!(check_with(&model, &record, &[0.3], past).is_err());
/// let empty = CheckPlan { score_from: 500, score_to: Some(500), ..plan };
/// assert!(check_with(&model, &record, &[0.3], empty).is_err());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// As [`check_record`], and a window that starts past the record.
pub fn check_with(
    sim: &dyn Simulator,
    record: &IoData,
    theta: &[f64],
    plan: CheckPlan,
) -> Result<RecordCheck, RefineError> {
    within_record(record, plan)?;
    let starts = plan.search().starts(sim.spec().prior(), theta, None)?;
    let best = search_best_fits(sim, vec![(record, starts)])
        .pop()
        .unwrap_or_else(|| unreachable!("one search, one result"))?;
    check_against(sim, record, theta, &best, plan)
}

/// [`check_with`] against a best-fit search already made on the record
/// through `sim` ([`search_best_fits`]): the check of a two-stage
/// estimate and of its refinement share one search, and no descent runs
/// here. The noise-free responses at the search's first start and at its
/// best are read back from the search's residuals (its output errors on
/// `record`), not simulated again: only the check's noisy runs, the `2q`
/// noise-free points of the response's span at `theta` (one batch), and
/// a `theta` the search did not start from, are simulated.
///
/// # Errors
/// As [`check_with`].
pub fn check_against(
    sim: &dyn Simulator,
    record: &IoData,
    theta: &[f64],
    best: &BestFit,
    plan: CheckPlan,
) -> Result<RecordCheck, RefineError> {
    within_record(record, plan)?;
    let window = plan.scored(record.n_samples());
    // The search evaluated its first start and its best: at either, the
    // response is read back from there, not simulated again.
    let searched = if same_bits(theta, &best.best.theta) {
        Some(best.best_residuals.as_slice())
    } else {
        best.first_start
            .as_ref()
            .filter(|start| same_bits(&start.theta, theta))
            .map(|start| start.residuals.as_slice())
    }
    .and_then(|residuals| response_from_output_errors(record, residuals));
    let simulated = match searched {
        Some(response) => response,
        None => noise_free(
            sim,
            theta,
            record,
            plan.seed,
            "the noise-free simulation at the estimate",
        )?,
    };
    let mut at_estimate = vec![0.0; record.n_samples() * record.n_outputs()];
    write_output_errors(record, &simulated, &mut at_estimate)?;
    let against = against_best(sim, record, theta, &simulated, &at_estimate, best, plan)?;
    let span = ResponseSpan::at(sim, record, theta, window.clone())?;
    let own = OwnRecords {
        simulated: &simulated,
        at_estimate: &at_estimate,
        span: &span,
    };
    let observed = Observed {
        misfit: mean_squares(record, &simulated, window.clone()),
        best_misfit: against.best_misfit,
        improved: span.window_loss(&at_estimate) - span.window_loss(&against.at_best),
    };
    let ranked = rank_among_own(sim, record, &own, &observed, theta, plan)?;
    let shared = sim
        .shared_input()
        .filter(|shared| shared.n_inputs() == record.n_inputs());
    let input_shared = shared.is_some();
    let input_differs_at = shared.and_then(|shared| first_difference(record, &shared));
    let (rms, fit_percent) = fits_over(record, &simulated, window);
    Ok(RecordCheck {
        rms,
        fit_percent,
        tail_probability: ranked.misfit,
        improvement_tail_probability: ranked.improvement,
        best_fit_tail_probability: ranked.best_misfit,
        reference_runs: ranked.runs,
        simulated,
        input_differs_at,
        input_shared,
        loss_ratio: against.loss_ratio,
        best_fit_percent: against.best_fit_percent,
        best_theta: best.best.theta.clone(),
        optima: best.optima.len(),
        runner_up_ratio: best.runner_up_ratio(),
    })
}

/// Per output of `record`, the RMS misfit and the normalized fit of
/// `simulated` over the samples `window` ([`output_fit`]).
fn fits_over(record: &IoData, simulated: &IoData, window: Range<usize>) -> (Vec<f64>, Vec<f64>) {
    (0..record.n_outputs())
        .map(|j| {
            output_fit(
                &record.output(j)[window.clone()],
                &simulated.output(j)[window.clone()],
            )
        })
        .unzip()
}

/// The best fit of each record from its starts (see
/// [`SearchStarts::starts`]), through `sim`'s output-error loss
/// ([`Refinement::best_fits`]): every record's descents in one lockstep,
/// so a simulator that answers a batch at the price of one point gets
/// full batches.
///
/// # Errors
/// Per record: a source that cannot simulate without noise on a given
/// input, or a record whose every start fails.
pub fn search_best_fits(
    sim: &dyn Simulator,
    searches: Vec<(&IoData, Vec<Vec<f64>>)>,
) -> Vec<Result<BestFit, RefineError>> {
    match OutputError::new(sim) {
        Ok(loss) => Refinement::new(loss).best_fits(searches),
        Err(e) => searches.iter().map(|_| Err(e.clone())).collect(),
    }
}

/// A scoring window of at least one sample, inside the record.
fn within_record(record: &IoData, plan: CheckPlan) -> Result<(), RefineError> {
    scoring_window(record.n_samples(), plan.score_from, plan.score_to).map(|_| ())
}

/// The samples scored of a record of `samples` samples, from `score_from`
/// up to `score_to` (not including it; `None`: the record's end), or why
/// that is no window: one of at least one sample, inside the record. The
/// check and `simulate --at --input` both ask it.
///
/// ```
/// use twostage_refine::scoring_window;
/// assert_eq!(scoring_window(1000, 100, Some(600)).ok(), Some(100..600));
/// assert_eq!(scoring_window(1000, 100, None).ok(), Some(100..1000));
/// let empty = scoring_window(1000, 100, Some(100)).unwrap_err().to_string();
/// assert!(empty.contains("the window must end after its start (100)"), "{empty}");
/// let past = scoring_window(1000, 1000, None).unwrap_err().to_string();
/// assert!(past.contains("the record has 1000 samples (0 to 999)"), "{past}");
/// ```
///
/// # Errors
/// An end not after the start or past the record, a start past the
/// record ([`RefineError::InvalidSetting`], named `score to` or `score
/// from`).
pub fn scoring_window(
    samples: usize,
    score_from: usize,
    score_to: Option<usize>,
) -> Result<Range<usize>, RefineError> {
    if let Some(to) = score_to
        && (to <= score_from || to > samples)
    {
        return Err(RefineError::InvalidSetting(InvalidSetting {
            name: "score to",
            value: to.to_string(),
            reason: format!(
                "the window must end after its start ({score_from}) and at most at the record's \
                 end ({samples} samples)"
            ),
        }));
    }
    if score_from >= samples {
        return Err(RefineError::InvalidSetting(InvalidSetting {
            name: "score from",
            value: score_from.to_string(),
            reason: format!(
                "the record has {samples} samples (0 to {})",
                samples.saturating_sub(1)
            ),
        }));
    }
    Ok(score_from..score_to.unwrap_or(samples))
}

/// Check `record` against `sim` at `theta`: one noise-free run on the
/// record's input and `noisy` runs with the model's noise (streams
/// `seed`, 0..noisy), whose misfits to the noise-free run are the
/// reference the record's misfit is ranked among.
///
/// ```
/// use twostage_models::{experiment_rng, PacejkaCar, Simulator};
/// use twostage_refine::check_record;
/// let car = PacejkaCar::builder().n_samples(300).build()?;
/// let mut record = car.spec().new_record();
/// car.simulate(&[-35.0, -1.1], &mut experiment_rng(7, 0), &mut record)?;
/// // At the truth the record is one of the model's own.
/// let right = check_record(&car, &record, &[-35.0, -1.1], 99, 1)?;
/// assert!(right.explained() && right.fit_percent[0] > 95.0);
/// // Far from it, the record's misfit exceeds every one of the model's.
/// let wrong = check_record(&car, &record, &[-25.0, -1.1], 99, 1)?;
/// assert!(!wrong.explained() && wrong.tail_probability == 0.01);
/// // Though the fit alone (95% against 97%) would not have said so.
/// assert!(wrong.fit_percent[0] > 90.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// What simulating says: a record of another length or inputs than the
/// model's, a source that cannot run without noise or on a given input,
/// a run that fails.
pub fn check_record(
    sim: &dyn Simulator,
    record: &IoData,
    theta: &[f64],
    noisy: usize,
    seed: u64,
) -> Result<RecordCheck, RefineError> {
    check_with(
        sim,
        record,
        theta,
        CheckPlan::new(noisy, seed, sim.spec().prior().dim()),
    )
}

/// The model's noise-free response at `theta` on `record`'s input.
fn noise_free(
    sim: &dyn Simulator,
    theta: &[f64],
    record: &IoData,
    seed: u64,
    what: &'static str,
) -> Result<IoData, RefineError> {
    let quiet = Conditions {
        noiseless: true,
        input: Some(record),
    };
    let mut simulated = IoData::default();
    sim.simulate_under(
        theta,
        &mut experiment_rng(seed, u64::MAX),
        quiet,
        &mut simulated,
    )
    .map_err(|source| RefineError::Simulation { what, source })?;
    Ok(simulated)
}

/// The model's noise-free response at an estimate and what the model's
/// own records there are compared by.
struct OwnRecords<'a> {
    /// The noise-free response.
    simulated: &'a IoData,
    /// The record's output errors at the estimate.
    at_estimate: &'a [f64],
    /// The span of the response near the estimate.
    span: &'a ResponseSpan,
}

/// What a record is ranked by among the model's own records.
struct Observed {
    /// Per output, the mean square of the record less the response at
    /// the estimate (over the scoring window).
    misfit: Vec<f64>,
    /// The same against the best fit's response.
    best_misfit: Vec<f64>,
    /// The best fit's loss below the estimate's over the window.
    improved: f64,
}

/// How a record ranks among the model's own records at its estimate.
struct Ranked {
    /// The tail probability of its misfit.
    misfit: f64,
    /// The tail probability of its best fit's improvement.
    improvement: f64,
    /// The tail probability of its misfit to its best fit.
    best_misfit: f64,
    /// How many of the model's records ran.
    runs: usize,
}

/// The record's misfits to the noise-free responses at the estimate and
/// at its best fit, and its best fit's improvement on the estimate, each
/// ranked among the model's own noisy records at `theta` (their misfits
/// to the estimate's response; their improvements to first order, through
/// the response's span).
fn rank_among_own(
    sim: &dyn Simulator,
    record: &IoData,
    own: &OwnRecords<'_>,
    observed: &Observed,
    theta: &[f64],
    plan: CheckPlan,
) -> Result<Ranked, RefineError> {
    let CheckPlan { noisy, seed, .. } = plan;
    let window = plan.scored(record.n_samples());
    let with_noise = Conditions {
        noiseless: false,
        input: Some(record),
    };
    // A run's misfit per output and its improvement: the run's output
    // errors less the estimate's are its noise, in the loss's weights.
    let compare = |run: &IoData| -> Result<(Vec<f64>, f64), RefineError> {
        let mut noise = vec![0.0; own.at_estimate.len()];
        write_output_errors(record, run, &mut noise)?;
        for (n, e) in noise.iter_mut().zip(own.at_estimate) {
            *n = e - *n;
        }
        Ok((
            mean_squares(run, own.simulated, window.clone()),
            own.span.improvement(&noise),
        ))
    };
    // Runs first..first + count, in the source's batches (a command answers
    // a batch in one request), spread over the threads so that a simulator
    // that does not vectorize uses every core; experiment i's stream is
    // (seed, i) whatever the split.
    let threads = rayon::current_num_threads().max(1);
    let runs = |first: usize, count: usize| -> Result<Vec<(Vec<f64>, f64)>, RefineError> {
        let size = sim.batch_size().max(1).min(count.div_ceil(threads)).max(1);
        let firsts: Vec<usize> = (first..first + count).step_by(size).collect();
        let done: Vec<Vec<(Result<(), _>, IoData)>> = firsts
            .par_iter()
            .map(|&from| {
                let k = size.min(first + count - from);
                let thetas = vec![theta; k];
                let mut rngs: Vec<_> = (from..from + k)
                    .map(|i| experiment_rng(seed, i as u64))
                    .collect();
                let mut own = vec![IoData::default(); k];
                let results = sim.simulate_batch_under(&thetas, &mut rngs, with_noise, &mut own);
                results.into_iter().zip(own).collect()
            })
            .collect();
        done.into_iter()
            .flatten()
            .map(|(result, run)| {
                result.map_err(|source| RefineError::Simulation {
                    what: "a simulation with the model's noise at the estimate",
                    source,
                })?;
                compare(&run)
            })
            .collect()
    };
    // Sequentially (Besag and Clifford, 1991, Biometrika 78(2)): the runs
    // come in blocks ending at fixed counts, whatever the thread count, and
    // stop once STOP_EXCEEDANCES of them miss (the estimate's response and
    // the best fit's) and improve by at least as much as the record, and
    // so many that the full run's tail probabilities, at least (g + 1) /
    // (noisy + 1), would be above the 1% level anyway: the verdicts are the
    // full run's; only the reported probabilities are the coarser (g + 1)
    // / (L + 1) of the L runs made.
    let ends = block_ends(noisy);
    let mut reference = runs(0, ends[0])?;
    // Each output's misfit in units of the model's own over the first
    // block (so that outputs of different scales weigh alike), summed over
    // the outputs.
    let scale: Vec<f64> = (0..record.n_outputs())
        .map(|j| reference.iter().map(|r| r.0[j]).sum::<f64>() / reference.len().max(1) as f64)
        .collect();
    let statistic = |ms: &[f64]| -> f64 {
        ms.iter()
            .zip(&scale)
            .map(|(m, s)| {
                if *s > 0.0 {
                    m / s
                } else if *m > 0.0 {
                    f64::INFINITY
                } else {
                    0.0
                }
            })
            .sum()
    };
    let (misfit, best_misfit) = (
        statistic(&observed.misfit),
        statistic(&observed.best_misfit),
    );
    let exceeding = |reference: &[(Vec<f64>, f64)]| {
        let beyond = |level: f64| {
            reference
                .iter()
                .filter(|r| statistic(&r.0) >= level)
                .count()
        };
        let improvements = reference
            .iter()
            .filter(|r| r.1 >= observed.improved)
            .count();
        [beyond(misfit), improvements, beyond(best_misfit)]
    };
    let settled =
        |g: usize| g >= STOP_EXCEEDANCES && (g + 1) as f64 / (noisy + 1) as f64 > EXPLAINED_LEVEL;
    for window in ends.windows(2) {
        if exceeding(&reference).into_iter().all(settled) {
            break;
        }
        reference.extend(runs(window[0], window[1] - window[0])?);
    }
    let [misfits, improvements, best_misfits] = exceeding(&reference);
    let share = |g: usize| (g + 1) as f64 / (reference.len() + 1) as f64;
    Ok(Ranked {
        misfit: share(misfits),
        improvement: share(improvements),
        best_misfit: share(best_misfits),
        runs: reference.len(),
    })
}

/// An estimate against its record's best fit.
struct AgainstBest {
    /// The output-error loss at the estimate over the best fit's.
    loss_ratio: f64,
    /// Per output, the best fit's normalized fit.
    best_fit_percent: Vec<f64>,
    /// The best fit's output errors.
    at_best: Vec<f64>,
    /// Per output, the mean square of the record less the best fit's
    /// response over the scoring window.
    best_misfit: Vec<f64>,
}

/// The estimate's fit against the search's best: the output-error loss at
/// the estimate (its output errors `at_estimate`, from its noise-free run
/// `simulated`) over the best fit's, and the best fit's fit, output errors
/// and misfit (its own run, unless it is the estimate).
fn against_best(
    sim: &dyn Simulator,
    record: &IoData,
    theta: &[f64],
    simulated: &IoData,
    at_estimate: &[f64],
    best: &BestFit,
    plan: CheckPlan,
) -> Result<AgainstBest, RefineError> {
    let window = plan.scored(record.n_samples());
    let estimate_loss: f64 = at_estimate.iter().map(|r| r * r).sum();
    let best_loss = best.best.loss;
    let loss_ratio = if best_loss > 0.0 {
        estimate_loss / best_loss
    } else if estimate_loss > 0.0 {
        f64::INFINITY
    } else {
        1.0
    };
    let own;
    let best_response = if same_bits(theta, &best.best.theta) {
        simulated
    } else {
        // The search's own residuals at its best, else a run there.
        own = match response_from_output_errors(record, &best.best_residuals) {
            Some(response) => response,
            None => noise_free(
                sim,
                &best.best.theta,
                record,
                plan.seed,
                "the noise-free simulation at the best fit",
            )?,
        };
        &own
    };
    let best_fit_percent = (0..record.n_outputs())
        .map(|j| {
            output_fit(
                &record.output(j)[window.clone()],
                &best_response.output(j)[window.clone()],
            )
            .1
        })
        .collect();
    let mut at_best = vec![0.0; at_estimate.len()];
    write_output_errors(record, best_response, &mut at_best)?;
    Ok(AgainstBest {
        loss_ratio,
        best_fit_percent,
        at_best,
        best_misfit: mean_squares(record, best_response, window),
    })
}

/// Whether two points are the same, bit for bit.
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

mod at_best_fit;
#[cfg(test)]
mod tests;
