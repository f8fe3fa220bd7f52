//! What a refinement descends and what one descent gives: the model whose
//! residuals make the loss, and a descent's end. The descents themselves
//! (`refinement.rs`, and `lockstep.rs` for many records at once) both read
//! these, so they stand apart from both.

use twostage_fit::TerminationReason;
use twostage_models::{IoData, Prior};

use crate::error::RefineError as Error;

/// A model whose prediction errors on a record can be computed at any theta:
/// the loss is the sum of their squares.
///
/// ```
/// use twostage_models::{IoData, Prior};
/// use twostage_refine::{RefineError, ResidualModel};
/// /// Outputs `theta` plus white noise: the residuals are `y_k - theta`.
/// struct ConstantMean(Prior);
/// impl ResidualModel for ConstantMean {
///     type Error = RefineError;
///     fn prior(&self) -> &Prior {
///         &self.0
///     }
///     fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), RefineError> {
///         for (r, y) in r.iter_mut().zip(record.output(0)) {
///             *r = y - theta[0];
///         }
///         Ok(())
///     }
/// }
/// # let _ = ConstantMean(Prior::uniform_box(&[0.0], &[1.0])?);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait ResidualModel: Send + Sync {
    /// What a failed evaluation returns; the refinement's own errors (a
    /// start of the wrong length, say) convert into it.
    type Error: From<Error> + Send;

    /// The prior box: the model is not evaluated outside it.
    fn prior(&self) -> &Prior;

    /// Write the residuals of `record` at `theta` into `residuals`, whose
    /// squares sum to the loss: prediction errors, one per sample, unless
    /// [`ResidualModel::n_residuals`] says otherwise.
    ///
    /// # Errors
    /// A record the model cannot use, or a prediction that fails.
    fn residuals(
        &self,
        theta: &[f64],
        record: &IoData,
        residuals: &mut [f64],
    ) -> Result<(), Self::Error>;

    /// How many residuals `record` gives (default: one per sample).
    fn n_residuals(&self, record: &IoData) -> usize {
        record.n_samples()
    }

    /// The lengths of the runs of `record`'s residuals that are each one
    /// stationary sequence in time (one per output of a record, one per
    /// output of each record of several), in order, summing to
    /// [`ResidualModel::n_residuals`]. An interval models each run's
    /// noise on its own ([`Refinement::uncertainty`]). Default: one run
    /// per output when the residuals are a multiple of the samples, else
    /// one.
    ///
    /// [`Refinement::uncertainty`]: crate::Refinement::uncertainty
    fn residual_runs(&self, record: &IoData) -> Vec<usize> {
        let n = self.n_residuals(record);
        let samples = record.n_samples();
        if samples > 0 && n.is_multiple_of(samples) {
            vec![samples; n / samples]
        } else {
            vec![n]
        }
    }

    /// The residuals of many `(theta, record)` pairs, one result each,
    /// into `residuals[k]` (resized to the pair's
    /// [`ResidualModel::n_residuals`]): what one round of the descents
    /// under way needs. Each pair's residuals must be those
    /// [`ResidualModel::residuals`] gives it alone. Default: the pairs in
    /// parallel on the threads; a model behind a process sends them in its
    /// batches ([`crate::OutputError`]).
    fn residuals_batch(
        &self,
        pairs: &[(&[f64], &IoData)],
        residuals: &mut [Vec<f64>],
    ) -> Vec<Result<(), Self::Error>> {
        use rayon::prelude::*;
        pairs
            .par_iter()
            .zip(residuals.par_iter_mut())
            .map(|((theta, record), r)| {
                r.resize(self.n_residuals(record), 0.0);
                self.residuals(theta, record, r)
            })
            .collect()
    }

    /// How many trial steps of increasing damping a descent asks for at
    /// once (default 1). More suits a model for which a few points cost
    /// about what one does (a batch to a process); the descent ends at the
    /// same point either way.
    fn trials_at_once(&self) -> usize {
        1
    }
}

impl<E: From<Error> + Send> ResidualModel for Box<dyn ResidualModel<Error = E>> {
    type Error = E;
    fn prior(&self) -> &Prior {
        (**self).prior()
    }
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<(), E> {
        (**self).residuals(theta, record, residuals)
    }
    fn n_residuals(&self, record: &IoData) -> usize {
        (**self).n_residuals(record)
    }
    fn residual_runs(&self, record: &IoData) -> Vec<usize> {
        (**self).residual_runs(record)
    }
    fn residuals_batch(
        &self,
        pairs: &[(&[f64], &IoData)],
        residuals: &mut [Vec<f64>],
    ) -> Vec<Result<(), E>> {
        (**self).residuals_batch(pairs, residuals)
    }
    fn trials_at_once(&self) -> usize {
        (**self).trials_at_once()
    }
}

/// One descent from one start.
#[derive(Debug, Clone, PartialEq)]
pub struct Descent {
    /// Where it started.
    pub start: Vec<f64>,
    /// Where it ended.
    pub theta: Vec<f64>,
    /// The loss there.
    pub loss: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: TerminationReason,
}

/// A point of a search with its residuals there.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluated {
    /// The point.
    pub theta: Vec<f64>,
    /// The residuals there.
    pub residuals: Vec<f64>,
}
