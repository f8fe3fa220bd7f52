//! The watch over one restart: the weights of the lowest held-out loss so
//! far, when patience has run out, and when the training's time is up.

use crate::levenberg_marquardt::TerminationReason;

use super::network::{Problem, RestartReport};
use super::params::MlpParams;

/// Keeps the weights with the lowest held-out loss and says when `patience`
/// checks have passed without improvement (never, when nothing is held out).
pub(crate) struct BestHeldOut {
    loss: f64,
    params: Vec<f64>,
    since: usize,
    patience: usize,
    active: bool,
}

impl BestHeldOut {
    /// The watch of a restart from `params` on `problem`'s held-out rows
    /// (its training rows when none are held out, where it never stops
    /// the training), and those rows.
    pub(super) fn start<'p>(
        problem: &Problem<'p>,
        params: &[f64],
        patience: usize,
    ) -> (Self, &'p [usize]) {
        let active = !problem.held_out.is_empty();
        let held_out = if active {
            problem.held_out
        } else {
            problem.train
        };
        let initial = problem.mse(params, held_out);
        (Self::new(initial, params, patience, active), held_out)
    }

    /// The watch from `params` at held-out `loss`, stopping after
    /// `patience` checks without improvement when `active`.
    pub(crate) fn new(loss: f64, params: &[f64], patience: usize, active: bool) -> Self {
        Self {
            loss,
            params: params.to_vec(),
            since: 0,
            patience,
            active,
        }
    }

    /// The restart's kept weights and its report, `iterations` run and
    /// stopped for `reason`.
    pub(super) fn into_restart(
        self,
        problem: &Problem<'_>,
        restart: usize,
        iterations: usize,
        reason: TerminationReason,
    ) -> (Vec<f64>, RestartReport) {
        let report = RestartReport {
            restart,
            iterations,
            reason,
            train_mse: problem.mse(&self.params, problem.train),
            validation_mse: self.loss,
        };
        (self.params, report)
    }

    /// Record the held-out loss of `params`; true when training should stop.
    pub(crate) fn observe(&mut self, loss: f64, params: &[f64]) -> bool {
        if loss < self.loss {
            self.loss = loss;
            self.params.copy_from_slice(params);
            self.since = 0;
            false
        } else {
            self.since += 1;
            self.active && self.since >= self.patience
        }
    }
}

impl BestHeldOut {
    /// The lowest held-out loss seen and its weights.
    pub(crate) fn into_best(self) -> (f64, Vec<f64>) {
        (self.loss, self.params)
    }
}

/// Whether the training's time is up (`Mlp::stopped_by`).
pub(super) fn out_of_time(mlp: &MlpParams) -> bool {
    past(mlp.stop_by)
}

/// Whether `stop_by`, where there is one, has come.
pub(crate) fn past(stop_by: Option<std::time::Instant>) -> bool {
    stop_by.is_some_and(|stop_by| std::time::Instant::now() >= stop_by)
}
