//! The prediction-error method (Section 2.2 of the paper): minimize the sum
//! of squared one-step prediction errors over theta in the prior box, by
//! Levenberg-Marquardt with finite-difference derivatives, from several
//! seeded random starts, keeping the lowest loss. The descent itself is the
//! facade's [`Refinement::descend`], the one that refines TS estimates.

use crate::InvalidSetting;
use twostage_models::{Benchmark, IoData, Prior, Simulator};
use twostage_refine::{Descent, Refinement, ResidualModel};

use crate::error::{BaselineError, Result};
use crate::kalman::benchmark_kalman_innovations;
use crate::{Estimate, RecordEstimator};

/// The benchmark with its exact Kalman predictor: the PE estimate is then
/// also the maximum-likelihood estimate up to the innovation variances.
#[derive(Debug, Clone)]
pub struct BenchmarkPredictor {
    prior: Prior,
}

impl BenchmarkPredictor {
    /// The paper's benchmark, theta in its prior's box [-0.9, 0.9].
    pub fn new() -> Self {
        Self {
            prior: Benchmark::new().spec().prior().clone(),
        }
    }
}

impl Default for BenchmarkPredictor {
    fn default() -> Self {
        Self::new()
    }
}

impl ResidualModel for BenchmarkPredictor {
    type Error = BaselineError;
    fn prior(&self) -> &Prior {
        &self.prior
    }
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<()> {
        benchmark_kalman_innovations(theta[0], record, Some(residuals)).map(|_| ())
    }
}

/// The prediction-error estimator with multi-start.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `starts` | 1 | >= 1 seeded uniform draws from the prior |
/// | `max_iterations` | 50 | >= 1 per start |
/// | `seed` | 0 | any |
///
/// ```
/// use twostage_baselines::{BenchmarkPredictor, PredictionError, RecordEstimator};
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.5], &mut experiment_rng(11, 0), &mut record)?;
/// let pem = PredictionError::new(BenchmarkPredictor::new(), 10).seed(1);
/// let descents = pem.descents(&record)?;
/// // The estimate is the end of the descent with the lowest loss; on this
/// // record it is the global minimum near the truth. (On others a local
/// // minimum a few hundredths away has almost the same loss: the
/// // sin(50 theta^2) term makes the loss oscillate, as the paper warns.)
/// assert!(descents.windows(2).all(|w| w[0].loss <= w[1].loss));
/// assert!((pem.estimate(&record)?.theta[0] - 0.5).abs() < 0.03);
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
#[derive(Debug, Clone)]
pub struct PredictionError<M> {
    search: Refinement<M>,
    starts: usize,
    max_iterations: usize,
    seed: u64,
    name: String,
}

impl<M: ResidualModel> PredictionError<M>
where
    BaselineError: From<M::Error>,
    M::Error: Send,
{
    /// PE with `starts` random starts.
    pub fn new(model: M, starts: usize) -> Self {
        Self {
            search: Refinement::new(model),
            starts,
            max_iterations: 50,
            seed: 0,
            name: format!("pem{starts}"),
        }
    }

    /// The seed of the starting points.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Another name for tables (default `pem<starts>`).
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// The residual model.
    pub fn model(&self) -> &M {
        self.search.model()
    }

    /// Iterations per start.
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self.search = self.search.max_iterations(iterations);
        self
    }

    /// One descent from `start`, as PE runs from each of its starts
    /// ([`Refinement::descend`]).
    ///
    /// # Errors
    /// A bad record, or a start of the wrong length.
    pub fn descend(&self, record: &IoData, start: Vec<f64>) -> Result<Descent> {
        Ok(self.search.descend(record, start)?)
    }

    /// Run every descent and return them all, best first.
    ///
    /// # Errors
    /// A bad record, or no start at all.
    pub fn descents(&self, record: &IoData) -> Result<Vec<Descent>> {
        if self.starts == 0 || self.max_iterations == 0 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "starts and iterations",
                value: format!("{} and {}", self.starts, self.max_iterations),
                reason: "at least 1 each".into(),
            }));
        }
        let prior = self.model().prior();
        let design = prior.design(self.starts, self.seed)?;
        let starts = (0..self.starts)
            .map(|i| {
                let mut start = vec![0.0; prior.dim()];
                design.fill_theta(i, &mut start).map(|()| start)
            })
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let mut descents = self.search.descents_from(record, starts)?;
        // Stable: equal losses keep the starts' order.
        descents.sort_by(|a, b| a.loss.total_cmp(&b.loss));
        Ok(descents)
    }
}

impl<M: ResidualModel> RecordEstimator for PredictionError<M>
where
    BaselineError: From<M::Error>,
    M::Error: Send,
{
    fn name(&self) -> &str {
        &self.name
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        let best = self.descents(record)?.into_iter().next().ok_or_else(|| {
            BaselineError::InvalidSetting(InvalidSetting {
                name: "starts",
                value: self.starts.to_string(),
                reason: "at least 1".into(),
            })
        })?;
        Ok(Estimate {
            theta: best.theta,
            spread: None,
        })
    }
}
