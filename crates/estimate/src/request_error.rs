//! What a request that cannot be prepared says: the part of it, and why.

/// What part of a request a [`RequestError`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// The classic method.
    Method,
    /// The multi-start output-error fit.
    OutputError,
    /// Given values.
    Given,
    /// The check of each estimate.
    Check,
    /// The refinement of each estimate.
    Refine,
    /// The joint fit of every record.
    Joint,
    /// The windows of each record.
    Windows,
    /// The model given.
    Model,
    /// The posterior's draws.
    Samples,
    /// Values tested against the posterior's region.
    Region,
    /// Parameters held at values.
    Fix,
}

impl Purpose {
    /// The purpose in a few words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Method => "the classic method",
            Self::OutputError => "the output-error fit",
            Self::Given => "checking given values",
            Self::Check => "the check",
            Self::Refine => "the refinement",
            Self::Joint => "the joint fit",
            Self::Windows => "the windows",
            Self::Model => "the model",
            Self::Samples => "the posterior's draws",
            Self::Region => "testing values against the posterior",
            Self::Fix => "holding parameters at values",
        }
    }
}

/// What went wrong preparing a request.
#[derive(Debug, thiserror::Error)]
pub enum RequestProblem {
    /// A method or check that simulates the model, and no model given.
    #[error("it simulates the model: give a built-in model or a model file")]
    NoModel,
    /// A refinement or a joint fit asked of another way of estimating
    /// than a trained estimator.
    #[error("it starts from a two-stage estimate and its interval: give a trained estimator")]
    NeedsEstimator,
    /// Values held with another way of estimating than a trained
    /// estimator.
    #[error(
        "values are held in a trained estimator's estimates and in its refinement through the \
         model: give a trained estimator (a classic method or the output-error fit takes a model \
         file with the values written in)"
    )]
    HeldNeedsEstimator,
    /// A window or a step of no samples.
    #[error(
        "a window of {length} samples every {every}: give a window and a step of at least 1 sample"
    )]
    EmptyWindow {
        /// Samples in a window.
        length: usize,
        /// Samples between windows.
        every: usize,
    },
    /// A file of given values that cannot be read or matched to records
    /// (the message names the file, line and column).
    #[error("{0}")]
    Values(String),
    /// Given values outside the model's prior box, not allowed.
    #[error("{from}, experiment {id}: {why}")]
    OutsidePrior {
        /// Where the values came from.
        from: String,
        /// The row's experiment.
        id: String,
        /// Which parameter lies where, and the box.
        why: String,
    },
    /// Draws that cannot be made (none asked, no posterior, a method
    /// that does not draw, more than memory holds).
    #[error("{0}")]
    Samples(String),
    /// A model given to a trained estimator's request that neither checks,
    /// refines nor fits its estimates jointly: it would be ignored.
    #[error(
        "a trained estimator reads a model only to check, refine or jointly fit its estimates, \
         and none is asked: leave the model out"
    )]
    ModelNotRead,
    /// A classic method asked of a model file.
    #[error(
        "method '{method}' is not available for {model}: the classic methods exist for the \
         built-in models only; train an estimator of the model file"
    )]
    NotBuiltIn {
        /// The method.
        method: &'static str,
        /// The model.
        model: String,
    },
    /// The model, the method or the estimator said no.
    #[error(transparent)]
    Failed(Box<dyn std::error::Error + Send + Sync>),
}

/// A request that cannot be prepared: what it was for, and why.
#[derive(Debug, thiserror::Error)]
#[error("{}: {error}", purpose.describe())]
pub struct RequestError {
    /// The part of the request.
    pub purpose: Purpose,
    /// Why.
    #[source]
    pub error: RequestProblem,
}

impl RequestError {
    pub(crate) fn new(purpose: Purpose, error: Box<dyn std::error::Error + Send + Sync>) -> Self {
        Self {
            purpose,
            error: RequestProblem::Failed(error),
        }
    }
}
