//! The output-error (simulation-error) loss of any simulator that can run
//! without noise on a given input: the record's outputs minus the model's
//! own response to the record's input. It needs no likelihood, so it
//! refines estimates of every model source: built-in, FMU, command.

use twostage_models::{Conditions, IoData, Prior, Simulator, experiment_rng};

use crate::RefineError;
use crate::refinement::ResidualModel;

/// The output-error residuals of `S`: for each output (scaled by the
/// record's own spread of that output, so that outputs in other units
/// weigh alike) and each sample, record minus noise-free simulation.
///
/// ```
/// use twostage_models::{experiment_rng, PacejkaCar, Simulator};
/// use twostage_refine::{OutputError, RefineStarts, Refinement};
/// let car = PacejkaCar::builder().n_samples(300).build()?;
/// let mut record = car.spec().new_record();
/// car.simulate(&[-35.0, -1.1], &mut experiment_rng(3, 0), &mut record)?;
/// // From a start 2 units off in pK1, within a box of +-4 and +-0.2.
/// let fit = Refinement::new(OutputError::new(&car)?);
/// let found = fit.refine(&record, &[-33.0, -1.15], &[4.0, 0.2], RefineStarts::Centre)?;
/// // The descent ends at a lower loss than the truth's (the noise moves the
/// // minimum, by about the Bayes error of pK1, 0.55, here 0.8).
/// use twostage_refine::ResidualModel;
/// let mut r = vec![0.0; fit.model().n_residuals(&record)];
/// fit.model().residuals(&[-35.0, -1.1], &record, &mut r)?;
/// assert!(found.loss <= r.iter().map(|v| v * v).sum::<f64>());
/// assert!((found.theta[0] + 35.0).abs() < 2.0 && (found.theta[1] + 1.1).abs() < 0.05);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct OutputError<S> {
    simulator: S,
}

impl<S: Simulator> OutputError<S> {
    /// The output-error loss of `simulator`.
    ///
    /// # Errors
    /// [`RefineError::Simulation`] for a source that cannot simulate
    /// without noise on a given input (the message says what can).
    pub fn new(simulator: S) -> Result<Self, RefineError> {
        let needed = Conditions {
            noiseless: true,
            input: Some(&IoData::default()),
        };
        simulator
            .capabilities()
            .check(&needed, simulator.spec().name())
            .map_err(|source| RefineError::Simulation {
                what: "an output-error fit",
                source,
            })?;
        Ok(Self { simulator })
    }

    /// The simulator.
    pub fn simulator(&self) -> &S {
        &self.simulator
    }
}

impl<S: Simulator> ResidualModel for OutputError<S> {
    type Error = RefineError;

    fn prior(&self) -> &Prior {
        self.simulator.spec().prior()
    }

    fn residuals(
        &self,
        theta: &[f64],
        record: &IoData,
        residuals: &mut [f64],
    ) -> Result<(), RefineError> {
        let mut response = IoData::default();
        self.simulate_quietly(theta, record, &mut response)?;
        write_output_errors(record, &response, residuals)
    }

    fn n_residuals(&self, record: &IoData) -> usize {
        record.n_samples() * record.n_outputs()
    }

    /// The pairs of each record (by its input) in the simulator's batches:
    /// a command source gets one request per batch of points (at most its
    /// `batch`, split over the threads when fewer), whatever the descents
    /// they come from; a simulator that takes one experiment at a time
    /// (built-in, FMU) runs the points on the threads.
    fn residuals_batch(
        &self,
        pairs: &[(&[f64], &IoData)],
        residuals: &mut [Vec<f64>],
    ) -> Vec<Result<(), RefineError>> {
        use rayon::prelude::*;
        let batch = self.simulator.batch_size();
        let mut results: Vec<Result<(), RefineError>> = vec![Ok(()); pairs.len()];
        let mut responses = vec![IoData::default(); pairs.len()];
        if batch <= 1 {
            results
                .par_iter_mut()
                .zip(responses.par_iter_mut())
                .zip(pairs)
                .for_each(|((result, response), (theta, record))| {
                    *result = self.simulate_quietly(theta, record, response);
                });
        } else {
            // Requests of at most `batch` points, spread over the threads so
            // that a simulator that does not vectorize uses every core.
            let threads = rayon::current_num_threads().max(1);
            let chunks: Vec<Vec<usize>> = same_input_groups(pairs)
                .into_iter()
                .flat_map(|group| {
                    let size = batch.min(group.len().div_ceil(threads)).max(1);
                    group
                        .chunks(size)
                        .map(<[usize]>::to_vec)
                        .collect::<Vec<_>>()
                })
                .collect();
            let answered: Vec<_> = chunks
                .par_iter()
                .map(|chunk| {
                    let record = pairs[chunk[0]].1;
                    let thetas: Vec<&[f64]> = chunk.iter().map(|&k| pairs[k].0).collect();
                    // A noise-free run draws nothing that matters: any streams serve.
                    let mut rngs: Vec<_> = (0..chunk.len())
                        .map(|k| experiment_rng(0, k as u64))
                        .collect();
                    let mut outs = vec![IoData::default(); chunk.len()];
                    let answers = self.simulator.simulate_batch_under(
                        &thetas,
                        &mut rngs,
                        quietly_on(record),
                        &mut outs,
                    );
                    (answers, outs)
                })
                .collect();
            for (chunk, (answers, outs)) in chunks.iter().zip(answered) {
                for ((&k, answer), out) in chunk.iter().zip(answers).zip(outs) {
                    results[k] = answer.map_err(simulation_error);
                    responses[k] = out;
                }
            }
        }
        for (((result, response), (_, record)), r) in results
            .iter_mut()
            .zip(&responses)
            .zip(pairs)
            .zip(residuals.iter_mut())
        {
            if result.is_ok() {
                r.resize(self.n_residuals(record), 0.0);
                *result = write_output_errors(record, response, r);
            }
        }
        results
    }

    /// A batched simulator asks for three trial dampings at once: a
    /// request costs it about the same for one point as for three.
    fn trials_at_once(&self) -> usize {
        if self.simulator.batch_size() > 1 {
            3
        } else {
            1
        }
    }
}

impl<S: Simulator> OutputError<S> {
    /// The noise-free response at `theta` to `record`'s input.
    fn simulate_quietly(
        &self,
        theta: &[f64],
        record: &IoData,
        response: &mut IoData,
    ) -> Result<(), RefineError> {
        // A noise-free run draws nothing that matters: any stream serves.
        self.simulator
            .simulate_under(
                theta,
                &mut experiment_rng(0, 0),
                quietly_on(record),
                response,
            )
            .map_err(simulation_error)
    }
}

/// Noise-free, on the record's input.
fn quietly_on(record: &IoData) -> Conditions<'_> {
    Conditions {
        noiseless: true,
        input: Some(record),
    }
}

fn simulation_error(source: twostage_models::SimError) -> RefineError {
    RefineError::Simulation {
        what: "the noise-free simulation of an output-error fit",
        source,
    }
}

/// The indices of `pairs` grouped by their records' inputs (the same
/// record, or one with the same input samples), in order of first
/// appearance: each group can go to the simulator as one request.
fn same_input_groups(pairs: &[(&[f64], &IoData)]) -> Vec<Vec<usize>> {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (k, (_, record)) in pairs.iter().enumerate() {
        let same = groups.iter_mut().find(|group| {
            let other = pairs[group[0]].1;
            std::ptr::eq(other, *record) || same_inputs(other, record)
        });
        match same {
            Some(group) => group.push(k),
            None => groups.push(vec![k]),
        }
    }
    groups
}

/// Whether two records hold the same input samples, bit for bit.
fn same_inputs(a: &IoData, b: &IoData) -> bool {
    a.n_samples() == b.n_samples()
        && a.n_inputs() == b.n_inputs()
        && (0..a.n_inputs()).all(|j| {
            a.input(j)
                .iter()
                .zip(b.input(j))
                .all(|(x, y)| x.to_bits() == y.to_bits())
        })
}

/// For each output (scaled by the record's own spread of that output, so
/// that outputs in other units weigh alike) and each sample: record minus
/// simulation.
///
/// # Errors
/// A response of another shape than the record (a simulator that returned
/// another length).
pub(crate) fn write_output_errors(
    record: &IoData,
    response: &IoData,
    residuals: &mut [f64],
) -> Result<(), RefineError> {
    let n = record.n_samples();
    if response.n_samples() != n || response.n_outputs() != record.n_outputs() {
        return Err(RefineError::Numerical {
            what: format!(
                "the simulation returned {} samples of {} output(s) for a record of {n} \
                 samples of {}",
                response.n_samples(),
                response.n_outputs(),
                record.n_outputs()
            ),
        });
    }
    for j in 0..record.n_outputs() {
        let y = record.output(j);
        let scale = output_scale(y);
        for ((r, y), s) in residuals[j * n..(j + 1) * n]
            .iter_mut()
            .zip(y)
            .zip(response.output(j))
        {
            *r = scale * (y - s);
        }
    }
    Ok(())
}

/// The weight of an output's errors: one over the record's own spread of
/// it (one for a constant output).
fn output_scale(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let mean = y.iter().sum::<f64>() / n;
    let spread = (y.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt();
    if spread > 0.0 { 1.0 / spread } else { 1.0 }
}

/// The noise-free response whose output errors on `record` are
/// `residuals` (as [`write_output_errors`] wrote them), on the record's
/// input: what a search already simulated, read back instead of run
/// again. `None` for residuals of another shape.
pub(crate) fn response_from_output_errors(record: &IoData, residuals: &[f64]) -> Option<IoData> {
    let n = record.n_samples();
    if residuals.len() != n * record.n_outputs() {
        return None;
    }
    let mut response = IoData::default();
    response.resize(n, record.n_inputs(), record.n_outputs());
    for j in 0..record.n_inputs() {
        response.input_mut(j).copy_from_slice(record.input(j));
    }
    for j in 0..record.n_outputs() {
        let y = record.output(j);
        let scale = output_scale(y);
        for ((s, y), r) in response
            .output_mut(j)
            .iter_mut()
            .zip(y)
            .zip(&residuals[j * n..(j + 1) * n])
        {
            *s = y - r / scale;
        }
    }
    Some(response)
}
