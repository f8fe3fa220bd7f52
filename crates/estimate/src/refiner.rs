//! Refining a two-stage estimate of one record through its model, as the
//! command line's `estimate --refine` and the Python package's
//! `Estimator.refine` both do: a built-in model's local posterior under its
//! exact likelihood, or for any other model an output-error fit through its
//! simulator, each with the refined estimate's own interval.

use std::sync::Arc;

use rayon::prelude::*;
use twostage_baselines::{BaselineError, exact_likelihood};
use twostage_estimator::Estimator;
use twostage_models::{IoData, Simulator};
use twostage_refine::{BestFit, OutputError, RefineError, Refinement, ResidualModel, SearchStarts};
use twostage_sources::{ModelProfile, Progress, Silent};

use crate::model_of::{EstimatorModel, SharedSimulator};

use twostage_fit::TerminationReason;

/// Why a record's best-fit search, check or refinement through its model
/// failed: the two-stage estimate is then the caller's to keep.
///
/// ```
/// use twostage::ModelFailure;
/// use twostage::refine::RefineError;
/// let failed = ModelFailure::Search(RefineError::Numerical { what: "every start's loss".into() });
/// assert_eq!(
///     failed.to_string(),
///     "the best-fit search failed: numerical failure: every start's loss"
/// );
/// ```
#[derive(Debug, Clone, thiserror::Error)]
#[non_exhaustive]
pub enum ModelFailure {
    /// The search's starts could not be placed (an interval or a radius
    /// that does not fit the parameters).
    #[error(transparent)]
    Starts(RefineError),
    /// The best-fit search from the starts failed.
    #[error("the best-fit search failed: {0}")]
    Search(RefineError),
    /// A check or an output-error refinement was asked for a record
    /// without a best-fit search.
    #[error("no best-fit search")]
    NoSearch,
    /// The check could not simulate the model at the estimate or the
    /// best fit.
    #[error(transparent)]
    Check(RefineError),
    /// A built-in model's local posterior could not be computed near the
    /// estimate.
    #[error(transparent)]
    Posterior(Arc<BaselineError>),
}

/// How a refined estimate was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RefinedBy {
    /// The posterior mean near the best fit (a built-in model's exact
    /// likelihood on a grid).
    PosteriorMean,
    /// An output-error descent, and why it stopped; with the search's
    /// optima where a search over the prior found its start.
    Descent {
        /// Why the descent stopped.
        stop: TerminationReason,
        /// The optima the search ended in, where one ran.
        optima: Option<SearchOptima>,
    },
}

/// The distinct optima an output-error search ended in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchOptima {
    /// How many distinct optima.
    pub count: usize,
    /// The runner-up's loss over the best's, where there is a runner-up.
    pub runner_up_over_best: Option<f64>,
}

/// A refined estimate of one record.
#[derive(Debug, Clone)]
pub struct RefinedEstimate {
    /// The refined parameters.
    pub theta: Vec<f64>,
    /// A posterior mean, or where an output-error descent stopped and
    /// the optima its search ended in.
    pub by: RefinedBy,
    /// The refined estimate's own interval half-widths, at the level of the
    /// estimator's intervals, or why it has none (the record does not
    /// determine some parameter).
    pub half_widths: std::result::Result<Vec<f64>, RefineError>,
    /// The parameters' correlation matrix (row-major q x q), where the
    /// interval has one.
    pub correlation: Option<Vec<f64>>,
}

/// A record to refine: the record, its two-stage estimate, and that
/// estimate's interval half-widths where the record has its own.
pub type ToRefine<'a> = (&'a IoData, &'a [f64], Option<&'a [f64]>);

/// How an estimator's estimates are refined: see [`EstimateRefiner::new`].
pub struct EstimateRefiner {
    how: How,
    /// The neighbourhood of a record without an interval of its own: the
    /// estimator's calibrated radius, twice its interval.
    radius: Vec<f64>,
    /// The level of the intervals (`1 - alpha`), the estimator's.
    alpha: f64,
    /// Where an output-error refinement's best-fit search starts besides
    /// the estimate and its interval's corners.
    search: SearchStarts,
}

enum How {
    Posterior {
        local: Refinement<Box<dyn ResidualModel<Error = BaselineError>>>,
        points: usize,
    },
    OutputError(Refinement<OutputError<SharedSimulator>>),
}

impl EstimateRefiner {
    /// The refinement of `estimator`'s estimates through its `model`.
    /// Without a model given a built-in model's estimates are refined to
    /// the posterior mean of its exact likelihood over twice the
    /// calibrated interval (the model's own grid), its interval the
    /// posterior mean plus or minus `z` posterior sds; with one, by an
    /// output-error fit through its simulator from the estimate and
    /// two starts inside its interval, the estimate the likelihood's mean
    /// within the prior's box near the best fit, its interval a sandwich
    /// from the record's residuals.
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::{EstimateRefiner, EstimatorModel};
    /// let estimator = TwoStage::builder(&Benchmark::new())
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(400).validation(0).calibration(200).seed(3).train()?;
    /// let refiner = EstimateRefiner::new(&estimator, &EstimatorModel::find(&estimator, None)?)?;
    /// let mut record = Benchmark::new().spec().new_record();
    /// Benchmark::new().simulate(&[0.3], &mut experiment_rng(8, 0), &mut record)?;
    /// let first = estimator.assess(&record)?;
    /// let refined = refiner.refine(&record, &first.theta, first.interval_half_widths())?;
    /// assert!(refined.half_widths.is_ok() && refined.by == twostage::RefinedBy::PosteriorMean);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// An estimator without intervals (no neighbourhood to refine in), or
    /// a model that cannot be built or run without noise on a given input.
    pub fn new(estimator: &Estimator, model: &EstimatorModel<'_>) -> twostage_train::Result<Self> {
        let radius = estimator.neighbourhood(2.0)?;
        // A neighbourhood exists only where the estimator has intervals.
        let alpha = estimator.intervals().map_or(0.1, |i| i.alpha());
        if let Some(builtin) = model.exact_likelihood() {
            return Ok(Self {
                how: How::Posterior {
                    local: Refinement::new(exact_likelihood(builtin)),
                    points: ModelProfile::of(builtin).refinement_points(),
                },
                radius,
                alpha,
                search: default_search(estimator),
            });
        }
        let fit = OutputError::new(model.simulator()?)?;
        Ok(Self {
            how: How::OutputError(Refinement::new(fit)),
            radius,
            alpha,
            search: default_search(estimator),
        })
    }

    /// Where an output-error refinement's best-fit search starts besides
    /// the estimate and its interval's corners (default:
    /// [`SearchStarts::default_from_prior`] starts of seed 0).
    pub fn search(mut self, search: SearchStarts) -> Self {
        self.search = search;
        self
    }

    /// Whether the refinement is an output-error fit (the best fit of a
    /// search, [`EstimateRefiner::refine_at`]), not a posterior mean.
    pub fn is_output_error(&self) -> bool {
        matches!(self.how, How::OutputError(_))
    }

    /// The starts of the best-fit search around `estimate`: its interval
    /// `half_widths` where the record has its own, else half the
    /// neighbourhood's.
    ///
    /// # Errors
    /// An estimate of another length than the model's parameters.
    pub fn search_starts(
        &self,
        prior: &twostage_models::Prior,
        estimate: &[f64],
        half_widths: Option<&[f64]>,
    ) -> std::result::Result<Vec<Vec<f64>>, RefineError> {
        let widths = half_widths.map_or_else(
            || self.radius.iter().map(|r| r / 2.0).collect(),
            <[f64]>::to_vec,
        );
        self.search.starts(prior, estimate, Some(&widths))
    }

    /// The simulator an output-error refinement runs (`None` for a
    /// posterior): a check of the refined estimates can share it, and its
    /// processes.
    pub fn simulator(&self) -> Option<&dyn Simulator> {
        match &self.how {
            How::OutputError(fit) => Some(fit.model().simulator().as_ref()),
            How::Posterior { .. } => None,
        }
    }

    /// Refines `estimate` of `record`, its interval `half_widths` where the
    /// record has its own (adaptive intervals), else half the
    /// neighbourhood.
    ///
    /// # Errors
    /// The model cannot be evaluated near the estimate: the two-stage
    /// estimate is then the caller's to keep.
    pub fn refine(
        &self,
        record: &IoData,
        estimate: &[f64],
        half_widths: Option<&[f64]>,
    ) -> std::result::Result<RefinedEstimate, ModelFailure> {
        self.refine_many(&[(record, estimate, half_widths)])
            .pop()
            .unwrap_or_else(|| unreachable!("one result per record"))
    }

    /// [`EstimateRefiner::refine`] of many records, one result per record
    /// in order: an output-error fit runs the descents of up to
    /// [`RECORDS_TOGETHER`] records in one lockstep and their intervals in
    /// one batch, so that a simulator costing the same for one point as
    /// for a batch is asked for full batches across the records; a
    /// built-in model's posteriors run over the threads. Each record's
    /// result is the one it gets alone.
    pub fn refine_many(
        &self,
        items: &[ToRefine<'_>],
    ) -> Vec<std::result::Result<RefinedEstimate, ModelFailure>> {
        self.refine_many_reporting(items, &Silent)
    }

    /// [`EstimateRefiner::refine_many`], reporting each `k` more records
    /// refined to `progress` ([`Progress::advance_step`] of the step the
    /// caller began).
    ///
    /// ```
    /// use std::sync::atomic::{AtomicUsize, Ordering};
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::{EstimateRefiner, EstimatorModel, Progress, TwoStage};
    /// #[derive(Default)]
    /// struct Count(AtomicUsize);
    /// impl Progress for Count {
    ///     fn advance_step(&self, done: usize) {
    ///         self.0.fetch_add(done, Ordering::Relaxed);
    ///     }
    /// }
    /// let estimator = TwoStage::builder(&Benchmark::new())
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(400).validation(0).calibration(200).seed(3).train()?;
    /// let refiner = EstimateRefiner::new(&estimator, &EstimatorModel::find(&estimator, None)?)?;
    /// let records: Vec<_> = (0..3u64)
    ///     .map(|i| {
    ///         let mut record = Benchmark::new().spec().new_record();
    ///         Benchmark::new().simulate(&[0.3], &mut experiment_rng(8, i), &mut record)?;
    ///         Ok(record)
    ///     })
    ///     .collect::<Result<_, twostage::models::SimError>>()?;
    /// let firsts: Vec<_> = records.iter().map(|r| estimator.assess(r)).collect::<Result<_, _>>()?;
    /// let items: Vec<_> = records
    ///     .iter()
    ///     .zip(&firsts)
    ///     .map(|(r, e)| (r, e.theta.as_slice(), e.interval_half_widths()))
    ///     .collect();
    /// let count = Count::default();
    /// let refined = refiner.refine_many_reporting(&items, &count);
    /// assert_eq!((refined.len(), count.0.load(Ordering::Relaxed)), (3, 3));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn refine_many_reporting(
        &self,
        items: &[ToRefine<'_>],
        progress: &dyn Progress,
    ) -> Vec<std::result::Result<RefinedEstimate, ModelFailure>> {
        let z = twostage_models::standard_normal_quantile(1.0 - self.alpha / 2.0);
        match &self.how {
            How::Posterior { local, points } => items
                .par_iter()
                .map(|(record, estimate, _)| {
                    let posterior = local
                        .local_posterior(record, estimate, &self.radius, *points)
                        .map_err(|e| ModelFailure::Posterior(Arc::new(e)))?;
                    progress.advance_step(1);
                    Ok(RefinedEstimate {
                        half_widths: Ok(posterior.sd.iter().map(|s| z * s).collect()),
                        correlation: Some(posterior.correlation),
                        theta: posterior.mean,
                        by: RefinedBy::PosteriorMean,
                    })
                })
                .collect(),
            How::OutputError(fit) => items
                .chunks(RECORDS_TOGETHER)
                .flat_map(|chunk| {
                    let refined = self.output_error(fit, chunk);
                    progress.advance_step(chunk.len());
                    refined
                })
                .collect(),
        }
    }

    /// The output-error refinement of `items`, together: each record's
    /// best-fit search, then its best fit's own interval.
    fn output_error(
        &self,
        fit: &Refinement<OutputError<SharedSimulator>>,
        items: &[ToRefine<'_>],
    ) -> Vec<std::result::Result<RefinedEstimate, ModelFailure>> {
        let prior = fit.model().prior();
        let starts: Vec<std::result::Result<Vec<Vec<f64>>, ModelFailure>> = items
            .iter()
            .map(|(_, estimate, half_widths)| {
                self.search_starts(prior, estimate, *half_widths)
                    .map_err(ModelFailure::Starts)
            })
            .collect();
        let searches = items
            .iter()
            .zip(&starts)
            .filter_map(|((record, _, _), starts)| Some((*record, starts.as_ref().ok()?.clone())))
            .collect();
        let mut found = fit.best_fits(searches).into_iter();
        let bests: Vec<std::result::Result<BestFit, ModelFailure>> = starts
            .into_iter()
            .map(|starts| {
                starts?;
                found
                    .next()
                    .unwrap_or_else(|| unreachable!("one search per record with starts"))
                    .map_err(ModelFailure::Search)
            })
            .collect();
        self.refine_at(items, &bests)
    }

    /// The output-error refinement of `items` at best fits already
    /// searched (one per item, as [`twostage_refine::search_best_fits`] gives
    /// them from [`EstimateRefiner::search_starts`]): each refined
    /// estimate is the mean near its record's best fit of the likelihood
    /// within the prior's box
    /// ([`twostage_refine::LocalUncertainty::mean_within_box`]: the best
    /// fit itself where the record pins a parameter down, pulled inside
    /// where it leaves one loose by a bound of the box), with its own
    /// interval from the loss's curvature there and the residuals'
    /// variance and autocorrelation, in one batch. No descent runs: the
    /// check of a two-stage estimate and its refinement share the search. A
    /// posterior refinement refines as [`EstimateRefiner::refine_many`]
    /// does and reads no search.
    pub fn refine_at(
        &self,
        items: &[ToRefine<'_>],
        bests: &[std::result::Result<BestFit, ModelFailure>],
    ) -> Vec<std::result::Result<RefinedEstimate, ModelFailure>> {
        let How::OutputError(fit) = &self.how else {
            return self.refine_many(items);
        };
        let prior = fit.model().prior();
        let refined: Vec<(&IoData, &[f64])> = items
            .iter()
            .zip(bests)
            .filter_map(|((record, _, _), best)| {
                Some((*record, best.as_ref().ok()?.best.theta.as_slice()))
            })
            .collect();
        let mut local = fit.uncertainties(&refined).into_iter();
        bests
            .iter()
            .map(|found| {
                let found = found.as_ref().map_err(Clone::clone)?;
                let best = &found.best;
                let local = local
                    .next()
                    .unwrap_or_else(|| unreachable!("one per refined record"));
                let theta = local.as_ref().map_or_else(
                    |_| best.theta.clone(),
                    |u| u.mean_within_box(&best.theta, prior.lower(), prior.upper()),
                );
                Ok(RefinedEstimate {
                    half_widths: local
                        .as_ref()
                        .map(|u| u.half_widths(self.alpha))
                        .map_err(Clone::clone),
                    correlation: local.ok().map(|u| u.correlation),
                    theta,
                    by: RefinedBy::Descent {
                        stop: best.stop,
                        optima: Some(SearchOptima {
                            count: found.optima.len(),
                            runner_up_over_best: found.runner_up_ratio(),
                        }),
                    },
                })
            })
            .collect()
    }
}

/// An estimator's default best-fit search: two starts per parameter and
/// two more from its prior, seed 0.
fn default_search(estimator: &Estimator) -> SearchStarts {
    SearchStarts {
        from_prior: SearchStarts::default_from_prior(estimator.param_names().len()),
        seed: 0,
    }
}

/// How many records an output-error refinement runs in one lockstep: their
/// points fill a simulator's batches; more would only hold more residuals
/// in memory at once.
pub const RECORDS_TOGETHER: usize = 64;
