//! Refining a parameter estimate with a least-squares loss through the
//! model, inside a neighbourhood of it: Levenberg-Marquardt descents
//! ([`Refinement::refine`]) or the posterior mean over the neighbourhood
//! ([`Refinement::local_posterior`]). The two-stage estimator picks the
//! neighbourhood (its calibrated intervals); the loss finds the answer
//! inside it. The same descent, started from draws of the prior, is the
//! prediction-error method of the paper's Section 2.2.
//!
//! The crate knows models and the one Levenberg-Marquardt solver, not the
//! estimator: any [`ResidualModel`] (an exact likelihood's prediction
//! errors, a simulation's output errors) can be refined.
#![deny(missing_docs)]

mod best_fit;
mod between;
mod check;
mod error;
mod improvement;
mod joint;
mod lockstep;
mod moments;
mod output_error;
mod policy;
mod refinement;
mod residual;
mod together;
mod uncertainty;

pub use best_fit::{
    BestFit, JOIN_DISTANCE, Optimum, SAME_OPTIMUM, SCREEN_SHARE, SearchStarts, spread_starts,
};
pub use between::{BetweenRecords, between_record_variance};
pub use check::{
    CheckPlan, DEFAULT_CHECK_RUNS, EXPLAINED_LEVEL, NEAR_BEST_LOSS, RecordCheck, STOP_EXCEEDANCES,
    check_against, check_record, check_with, output_fit, scoring_window, search_best_fits,
};
pub use error::{InvalidSetting, RefineError};
pub use joint::{JointEstimate, JointPlan, PooledEstimate, SingleEstimate, pool_estimates};
pub use moments::WeightedMoments;
pub use output_error::OutputError;
pub use policy::{RefinePolicy, RefineReason};
pub use refinement::{Descent, LocalPosterior, RefineStarts, Refinement, ResidualModel};
pub use residual::Evaluated;
/// Why a descent stopped ([`Descent::stop`]).
pub use twostage_fit::TerminationReason;
pub use uncertainty::LocalUncertainty;
