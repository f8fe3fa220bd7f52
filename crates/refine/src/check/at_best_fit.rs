//! A check moved to the best fit it was made against, without running
//! the model again.

use twostage_models::IoData;

use super::{CheckPlan, RecordCheck, fits_over};
use crate::best_fit::BestFit;
use crate::output_error::response_from_output_errors;

impl RecordCheck {
    /// This check (made by [`crate::check_against`] against `best`, the
    /// search on `record`, with `plan`) as a check of `best`'s best fit
    /// itself, read from what it already holds: the response and fit at
    /// the best fit are the search's, the misfit's tail probability there
    /// is [`Self::best_fit_tail_probability`] (the same statistic among
    /// the same runs), the best fit improves on itself by nothing (tail
    /// probability 1) and its loss is the best's (`loss_ratio` 1). The
    /// model's own records stay those run at the first estimate, a
    /// neighbour of the best fit: no simulation runs. `None` where the
    /// search's residuals are not the record's outputs'.
    pub fn at_best_fit(&self, record: &IoData, best: &BestFit, plan: CheckPlan) -> Option<Self> {
        let simulated = response_from_output_errors(record, &best.best_residuals)?;
        let (rms, fit_percent) = fits_over(record, &simulated, plan.scored(record.n_samples()));
        Some(Self {
            rms,
            fit_percent,
            tail_probability: self.best_fit_tail_probability,
            improvement_tail_probability: 1.0,
            simulated,
            loss_ratio: 1.0,
            best_theta: best.best.theta.clone(),
            ..self.clone()
        })
    }
}
