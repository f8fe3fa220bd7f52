//! Draws sharpened through the model (`samples` with `sharpen`): the
//! estimator's posterior proposes where to run the model, the runs'
//! stage-1 features near the record give a local likelihood, and its
//! product with the prior is drawn. Three rounds: each runs where the
//! round before put the posterior (a likelihood linear in the parameters,
//! drawn exactly). The last fits the features' mean window by window
//! ([`windowed::Windowed`]) where that predicts the runs better than one
//! quadratic; else it reads the features by the combinations a quadratic
//! fit of the round before found informative ([`local::Summary`]), with
//! a mean quadratic in the parameters ([`curved::Curved`]); either is
//! drawn by weights. A long record is read by its second moments
//! ([`moments`]), a short one by stage 1's features.

mod curved;
mod local;
mod moments;
mod windowed;

use rayon::prelude::*;
use twostage_estimator::{EstimateWorkspace, Estimator};
use twostage_kernels::mixture::Support;
use twostage_models::{
    Conditions, IoData, Marginal, Simulator, StreamPurpose, experiment_rng, stream_rng,
};
use twostage_sources::Progress;

use super::Estimating;
use super::failure::{MethodFailure, RecordFailure};
use super::rows::RecordOutcome;
use crate::{PosteriorDraws, RequestProblem};
use curved::{Curved, LastRoundLikelihood, curved_combinations, draw_by_weights};
use local::{Gaussian, Summary, draw_with_prior, local_likelihood};
use moments::{MOMENT_LAGS, MOMENTS_FROM, second_moments};
use windowed::Windowed;

/// Rounds of runs: the first where the estimator's posterior lies, each
/// next where the round before put it (a network's posterior several of
/// its sds off is found in two).
pub(crate) const ROUNDS: usize = 3;
/// How much wider than the posterior each round runs the model: the
/// local likelihood's slopes are measured across more than the
/// posterior's spread, its mean stays within the region it is fitted on.
const WIDEN: f64 = 1.5;
/// Draws that give a round's proposal its mean and spread.
const PROPOSAL_DRAWS: usize = 4000;

/// A record's draws of a round (unbounded, row after row) and the
/// combinations its features are read by, or why there are none.
type Drawn = Result<(Vec<f64>, Option<Summary>), String>;

/// The model runs of one round of one record, and where they ran.
struct Round {
    /// The unbounded parameters of the runs, row after row.
    at: Vec<f64>,
    /// The runs' parameters.
    thetas: Vec<Vec<f64>>,
}

impl Estimating {
    /// Each estimated record's draws sharpened through the model with
    /// `simulations` runs of it (a third a round), the records' runs of a
    /// round simulated together; a record whose runs or fit fail gets the
    /// failure, named by `place` of its id.
    pub(super) fn sharpen(
        &self,
        rows: &mut [(String, RecordOutcome)],
        place: &(dyn Fn(&str) -> String + Sync),
        progress: &dyn Progress,
    ) {
        let (Some(simulations), Some(model), Some(samples)) =
            (self.sharpen, self.sharpener.as_deref(), self.samples)
        else {
            return;
        };
        let super::methods::Method::TwoStage { estimator, .. } = &self.method else {
            return;
        };
        let prior: Vec<Marginal> = model.spec().prior().marginals().to_vec();
        let supports: Vec<Support> = prior.iter().map(Marginal::support).collect();
        let q = prior.len();
        let per_round = simulations.div_ceil(ROUNDS);
        let seed = self.plan.seed;
        // Each record's proposal: the estimator's posterior, as a Gaussian
        // over the unbounded parameters.
        let mut proposals: Vec<Option<Result<Gaussian, String>>> = rows
            .par_iter()
            .enumerate()
            .map(|(index, (_, outcome))| {
                let (record, _) = outcome.as_ref().ok()?;
                Some(first_proposal(estimator, record, &supports, (seed, index)))
            })
            .collect();
        let mut finals: Vec<Option<Result<Vec<f64>, String>>> = vec![None; rows.len()];
        let mut summaries: Vec<Option<Summary>> = vec![None; rows.len()];
        settle_failures(&mut proposals, &mut finals);
        progress.begin_step("sharpening", ROUNDS, "rounds");
        for round in 0..ROUNDS {
            let last = round + 1 == ROUNDS;
            let rounds: Vec<Option<Round>> = proposals
                .iter()
                .enumerate()
                .map(|(index, proposal)| {
                    let Some(Ok(proposal)) = proposal else {
                        return None;
                    };
                    let mut rng = stream_rng(
                        round_seed(seed, round),
                        index as u64,
                        StreamPurpose::Posterior,
                    );
                    let mut at = vec![0.0; per_round * q];
                    for z in at.chunks_exact_mut(q) {
                        proposal.draw(&mut rng, z);
                    }
                    let thetas = at
                        .chunks_exact(q)
                        .map(|z| {
                            z.iter()
                                .zip(&supports)
                                .map(|(v, s)| s.from_unbounded(*v))
                                .collect()
                        })
                        .collect();
                    Some(Round { at, thetas })
                })
                .collect();
            let features = run_rounds(model, estimator, rows, &rounds, round_seed(seed, round));
            let drawn: Vec<Option<Drawn>> = rows
                .par_iter()
                .enumerate()
                .zip(rounds.par_iter().zip(features))
                .zip(summaries.par_iter().zip(proposals.par_iter()))
                .map(
                    |(((index, (_, outcome)), (ran, features)), (summary, proposal))| {
                        let (record, _) = outcome.as_ref().ok()?;
                        let ran = ran.as_ref()?;
                        let Some(Ok(proposal)) = proposal else {
                            return None;
                        };
                        Some(features.and_then(|(features, p)| {
                            let observed = &read_of(estimator, record)?;
                            let mut rng = stream_rng(
                                round_seed(seed, round) ^ 0x5348_4152,
                                index as u64,
                                StreamPurpose::Posterior,
                            );
                            if last {
                                let likelihood = last_likelihood(
                                    &ran.at,
                                    q,
                                    (&features, p),
                                    observed,
                                    summary.as_ref(),
                                )?;
                                let draws = draw_by_weights(
                                    &*likelihood,
                                    &prior,
                                    proposal,
                                    samples,
                                    &mut rng,
                                )?;
                                return Ok((draws, None));
                            }
                            let likelihood = local_likelihood(&ran.at, q, &features, p, observed)?;
                            let draws =
                                draw_with_prior(&likelihood, &prior, PROPOSAL_DRAWS, &mut rng)?;
                            // The round before the last finds the
                            // combinations the last reads.
                            let combinations = (round + 2 == ROUNDS)
                                .then(|| curved_combinations(&ran.at, q, &features, p))
                                .transpose()?;
                            Ok((draws, combinations))
                        }))
                    },
                )
                .collect();
            proposals = drawn
                .into_iter()
                .enumerate()
                .map(|(index, drawn)| match drawn? {
                    Err(why) => Some(Err(why)),
                    Ok((draws, _)) if last => {
                        finals[index] = Some(Ok(draws));
                        None
                    }
                    Ok((draws, summary)) => {
                        summaries[index] = summary;
                        Some(Gaussian::of_draws(&draws, q, WIDEN))
                    }
                })
                .collect();
            settle_failures(&mut proposals, &mut finals);
            progress.advance_step(1);
        }
        progress.end_step();
        for ((id, outcome), done) in rows.iter_mut().zip(finals) {
            let Some(done) = done else { continue };
            match done {
                Ok(unbounded) => {
                    if let Ok((_, estimate)) = outcome {
                        let draws = unbounded
                            .chunks_exact(q)
                            .flat_map(|z| {
                                z.iter().zip(&supports).map(|(v, s)| s.from_unbounded(*v))
                            })
                            .collect();
                        estimate.posterior = Some(PosteriorDraws::of(draws, q));
                    }
                }
                Err(why) => {
                    *outcome = Err(RecordFailure::NotEstimated {
                        place: place(id),
                        why: MethodFailure::Sharpen(why),
                    });
                }
            }
        }
    }
}

/// What sharpening reads of a record or a run: its second moments
/// ([`second_moments`]) where it is long enough for them to be near
/// Gaussian, else stage 1's features.
fn read_of(estimator: &Estimator, record: &IoData) -> Result<Vec<f64>, String> {
    if record.n_samples() >= MOMENTS_FROM {
        return Ok(second_moments(record, MOMENT_LAGS));
    }
    estimator
        .features_of(
            record.inputs(),
            record.outputs(),
            &mut EstimateWorkspace::new(),
        )
        .map(<[f64]>::to_vec)
        .map_err(|e| e.to_string())
}

/// The last round's likelihood of the record's `observed` features given
/// the runs at `at` (rows of `q`) and their `features` (rows of `p`): a
/// mean fitted window by window on all the features where windows predict
/// the runs' features better than one quadratic ([`Windowed`]; one
/// quadratic's combinations keep too little of a mean that bends
/// faster); else the features read by the combinations the round before
/// found informative (`summary`), their mean one quadratic ([`Curved`]).
fn last_likelihood(
    at: &[f64],
    q: usize,
    (features, p): (&[f64], usize),
    observed: &[f64],
    summary: Option<&Summary>,
) -> Result<Box<dyn LastRoundLikelihood>, String> {
    if let Some(windowed) = Windowed::choose(at, q, features, p, observed) {
        return Ok(Box::new(windowed));
    }
    Ok(Box::new(Curved::fit_read_by(
        summary,
        at,
        q,
        (features, p),
        observed,
    )?))
}

/// Why draws cannot be sharpened through the model as asked: no runs,
/// no draws asked, or values to test against the posterior (whose region
/// is the network's density, which sharpened draws leave behind).
///
/// ```
/// assert!(twostage::sharpen_refused(Some(400), None, false).is_some());
/// assert!(twostage::sharpen_refused(Some(400), Some(1000), false).is_none());
/// assert!(twostage::sharpen_refused(None, Some(1000), true).is_none());
/// ```
pub fn sharpen_refused(
    simulations: Option<usize>,
    samples: Option<usize>,
    region: bool,
) -> Option<RequestProblem> {
    let simulations = simulations?;
    let why = if samples.is_none() {
        "sharpening works on the posterior's draws: ask for draws too (--samples N)"
    } else if simulations < 2 * ROUNDS {
        "sharpening takes runs of the model in three rounds: give at least 6 (a thousand or \
         more per parameter is typical)"
    } else if region {
        "values are tested against the network's posterior density, which sharpened draws \
         leave: test them without sharpening"
    } else {
        return None;
    };
    Some(RequestProblem::Samples(why.into()))
}

/// A record whose proposal failed is done: its failure moves to `finals`.
fn settle_failures(
    proposals: &mut [Option<Result<Gaussian, String>>],
    finals: &mut [Option<Result<Vec<f64>, String>>],
) {
    for (proposal, done) in proposals.iter_mut().zip(finals) {
        if let Some(Err(why)) = proposal.take_if(|p| p.is_err()) {
            *done = Some(Err(why));
        }
    }
}

/// The seed of a round's streams.
fn round_seed(seed: u64, round: usize) -> u64 {
    seed ^ (0x5348_4152_5045_4e00 + round as u64)
}

/// The estimator's posterior given `record` as a Gaussian over the
/// unbounded parameters, widened [`WIDEN`] times.
fn first_proposal(
    estimator: &Estimator,
    record: &IoData,
    supports: &[Support],
    (seed, index): (u64, usize),
) -> Result<Gaussian, String> {
    let q = supports.len();
    let mut draws = vec![0.0; PROPOSAL_DRAWS * q];
    let mut rng = stream_rng(
        round_seed(seed, ROUNDS),
        index as u64,
        StreamPurpose::Posterior,
    );
    estimator
        .sample_into(
            record.inputs(),
            record.outputs(),
            &mut EstimateWorkspace::new(),
            &mut rng,
            &mut draws,
        )
        .map_err(|e| e.to_string())?;
    for z in draws.chunks_exact_mut(q) {
        for (v, s) in z.iter_mut().zip(supports) {
            *v = s.to_unbounded(*v);
        }
    }
    Gaussian::of_draws(&draws, q, WIDEN)
}

/// Stage 1's features of every record's runs of a round (rows of `p`,
/// with `p`), each on its record's input with the model's noise; the runs
/// of all records in the simulator's batches, spread over the threads.
/// Run `k` of record `i` has the stream (`seed`, `i` x 2^32 + `k`),
/// whatever the split.
fn run_rounds(
    model: &dyn Simulator,
    estimator: &Estimator,
    rows: &[(String, RecordOutcome)],
    rounds: &[Option<Round>],
    seed: u64,
) -> Vec<Result<(Vec<f64>, usize), String>> {
    let jobs: Vec<(usize, usize)> = rounds
        .iter()
        .enumerate()
        .filter_map(|(i, r)| Some((i, r.as_ref()?.thetas.len())))
        .flat_map(|(i, n)| (0..n).map(move |k| (i, k)))
        .collect();
    let threads = rayon::current_num_threads().max(1);
    let size = model
        .batch_size()
        .max(1)
        .min(jobs.len().div_ceil(threads))
        .max(1);
    let done: Vec<Vec<Result<Vec<f64>, String>>> = jobs
        .par_chunks(size)
        .map(|chunk| {
            // One request holds runs of one record (one input).
            let mut answers = Vec::with_capacity(chunk.len());
            for same in chunk.chunk_by(|a, b| a.0 == b.0) {
                let i = same[0].0;
                let (Ok((record, _)), Some(round)) = (&rows[i].1, &rounds[i]) else {
                    continue;
                };
                let thetas: Vec<&[f64]> = same.iter().map(|&(_, k)| &round.thetas[k][..]).collect();
                let mut rngs: Vec<_> = same
                    .iter()
                    .map(|&(i, k)| experiment_rng(seed, ((i as u64) << 32) + k as u64))
                    .collect();
                let mut outs = vec![IoData::default(); same.len()];
                let with_noise = Conditions {
                    noiseless: false,
                    input: Some(record),
                };
                let results = model.simulate_batch_under(&thetas, &mut rngs, with_noise, &mut outs);
                for (result, run) in results.into_iter().zip(&outs) {
                    answers.push(
                        result
                            .map_err(|e| format!("a run of the model failed: {e}"))
                            .and_then(|()| {
                                read_of(estimator, run)
                                    .map_err(|e| format!("a run could not be compressed: {e}"))
                            }),
                    );
                }
            }
            answers
        })
        .collect();
    let mut flat = done.into_iter().flatten();
    rounds
        .iter()
        .map(|round| {
            let Some(round) = round else {
                return Err(String::new());
            };
            let runs: Vec<Result<Vec<f64>, String>> =
                flat.by_ref().take(round.thetas.len()).collect();
            if runs.len() < round.thetas.len() {
                return Err("a run was not made".into());
            }
            let mut features = Vec::new();
            let mut p = 0;
            for one in runs {
                let one = one?;
                p = one.len();
                features.extend(one);
            }
            Ok((features, p))
        })
        .collect()
}
