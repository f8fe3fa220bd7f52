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
        let quiet = Conditions {
            noiseless: true,
            input: Some(record),
        };
        let mut response = IoData::default();
        // A noise-free run draws nothing that matters: any stream serves.
        self.simulator
            .simulate_under(theta, &mut experiment_rng(0, 0), quiet, &mut response)
            .map_err(|source| RefineError::Simulation {
                what: "the noise-free simulation of an output-error fit",
                source,
            })?;
        let n = record.n_samples();
        for j in 0..record.n_outputs() {
            let y = record.output(j);
            let mean = y.iter().sum::<f64>() / n.max(1) as f64;
            let spread =
                (y.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n.max(1) as f64).sqrt();
            let scale = if spread > 0.0 { 1.0 / spread } else { 1.0 };
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

    fn n_residuals(&self, record: &IoData) -> usize {
        record.n_samples() * record.n_outputs()
    }
}
