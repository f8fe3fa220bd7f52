//! An estimate request's work through the model: each record's best-fit
//! search, its check, its refinement, and the joint fit of every record.

use rayon::prelude::*;
use twostage_models::IoData;
use twostage_refine::{BestFit, RecordCheck, RefineError, check_against, search_best_fits};
use twostage_sources::Progress;

use super::Estimating;
use super::rows::{Plant, RecordEstimate, RecordOutcome, RefineOutcome, Refined};
use crate::{
    EstimateRefiner, JointOfRecords, ModelFailure, RECORDS_TOGETHER, RefinedBy, SearchOptima,
    ToRefine,
};

/// A record's best-fit search, or why it failed; `None` where no check or
/// refinement needs one.
pub(super) type Search = Option<Result<BestFit, ModelFailure>>;

impl Estimating {
    /// Each record's best-fit search (from its estimate, its interval's
    /// corners and the prior), where a check or an output-error refinement
    /// needs one: the records together, in lockstep, a batch of them at a
    /// time.
    pub(super) fn search(
        &self,
        rows: &[(String, RecordOutcome)],
        progress: &dyn Progress,
    ) -> Vec<Search> {
        let refiner = self.refiner.as_ref().filter(|r| r.is_output_error());
        let Some(model) = refiner
            .and_then(EstimateRefiner::simulator)
            .or(self.check_model())
        else {
            return vec![None; rows.len()];
        };
        let prior = model.spec().prior();
        let starts: Vec<Option<Result<Vec<Vec<f64>>, ModelFailure>>> = rows
            .iter()
            .map(|(_, outcome)| {
                let (_, e) = outcome.as_ref().ok()?;
                let widths = e.half_widths.as_deref();
                Some(
                    match refiner {
                        Some(r) => r.search_starts(prior, &e.theta, widths),
                        None => self.plan.search().starts(prior, &e.theta, widths),
                    }
                    .map_err(ModelFailure::Starts),
                )
            })
            .collect();
        let wanted = starts.iter().filter(|s| matches!(s, Some(Ok(_)))).count();
        progress.begin_step("searching", wanted, "records");
        let mut found = Vec::with_capacity(wanted);
        let searches: Vec<(&IoData, Vec<Vec<f64>>)> = rows
            .iter()
            .zip(&starts)
            .filter_map(|((_, outcome), starts)| {
                let (record, _) = outcome.as_ref().ok()?;
                Some((record, starts.as_ref()?.as_ref().ok()?.clone()))
            })
            .collect();
        let mut searches = searches.into_iter();
        loop {
            let chunk: Vec<_> = searches.by_ref().take(RECORDS_TOGETHER).collect();
            if chunk.is_empty() {
                break;
            }
            let k = chunk.len();
            found.extend(search_best_fits(model, chunk));
            progress.advance_step(k);
        }
        progress.end_step();
        let mut found = found.into_iter();
        starts
            .into_iter()
            .map(|starts| match starts? {
                Ok(_) => Some(
                    found
                        .next()
                        .unwrap_or_else(|| unreachable!("one search per record with starts"))
                        .map_err(ModelFailure::Search),
                ),
                Err(e) => Some(Err(e)),
            })
            .collect()
    }

    /// Checks the estimates of the rows marked in `only`, in parallel,
    /// against their searches.
    pub(super) fn check_all(
        &self,
        rows: &mut [(String, RecordOutcome)],
        only: &[bool],
        searches: &[Search],
        progress: &dyn Progress,
    ) {
        let Some(model) = self.check_model() else {
            return;
        };
        progress.begin_step("checking", only.iter().filter(|o| **o).count(), "records");
        rows.par_iter_mut()
            .zip(only)
            .zip(searches)
            .filter(|((_, only), _)| **only)
            .for_each(|(((_, outcome), _), search)| {
                if let Ok((record, estimated)) = outcome {
                    estimated.check = Some(check(model, record, estimated, search, self));
                }
                progress.advance_step(1);
            });
        progress.end_step();
    }

    /// The refined rows marked in `only` whose check finds that the model
    /// does not make the record even at its best fit
    /// ([`RecordCheck::best_fit_consistent`] false: a plant the model
    /// misses part of) take their best fit itself as the estimate, their
    /// interval centred on it, and their check moved there
    /// ([`RecordCheck::at_best_fit`]: no simulation). The posterior mean
    /// near the best fit, which a refinement reports otherwise, weighs the
    /// likelihood of a model that makes the record; on one it does not,
    /// that likelihood's sandwich holds the model's error, and the mean
    /// moved a loose parameter away from the best fit at a cost in fit
    /// the records' noise does not explain.
    pub(super) fn settle_on_best_fits(
        &self,
        rows: &mut [(String, RecordOutcome)],
        only: &[bool],
        searches: &[Search],
    ) {
        if !self
            .refiner
            .as_ref()
            .is_some_and(EstimateRefiner::is_output_error)
        {
            return;
        }
        for (((_, outcome), search), marked) in rows.iter_mut().zip(searches).zip(only) {
            let (Ok((record, e)), Some(Ok(found)), true) = (outcome, search, *marked) else {
                continue;
            };
            let Some(Ok(check)) = &e.check else { continue };
            if e.refined().is_none() || check.best_fit_consistent() || e.theta == found.best.theta {
                continue;
            }
            let Some(moved) = check.at_best_fit(record, found, self.plan) else {
                continue;
            };
            e.theta.clone_from(&found.best.theta);
            e.check = Some(Ok(moved));
        }
    }

    /// An empty gathering of the records of one plant, for
    /// [`Self::fit_plant`]: it gathers nothing unless the request asked
    /// for the joint fit.
    ///
    /// ```
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::{EstimateRequest, EstimateWith, Silent, TwoStage};
    /// let model = Benchmark::new();
    /// let estimator = TwoStage::builder(&model)
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(400).validation(0).calibration(200).seed(3).train()?;
    /// let records = (0..2).map(|k| {
    ///     let mut record = model.spec().new_record();
    ///     model.simulate(&[0.4], &mut experiment_rng(9, k), &mut record).map(|()| (k.to_string(), Ok(record)))
    /// }).collect::<Result<Vec<_>, _>>()?;
    /// let estimating = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator)))
    ///     .joint(true)
    ///     .prepare()?;
    /// let mut plant = estimating.plant();
    /// // Batches from any number of files, each record named by its place.
    /// plant.gather(&estimating.estimate("a.csv", records, &Silent), |id| format!("a.csv: {id}"));
    /// let (joint, row) = estimating.fit_plant(&plant, &Silent).expect("asked").map_err(|e| e.to_string())?;
    /// assert_eq!(plant.places(), ["a.csv: 0", "a.csv: 1"]);
    /// assert!((row.theta[0] - 0.4).abs() < 0.1 && joint.theta == row.theta);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn plant(&self) -> Plant {
        Plant::new(self.joins())
    }

    /// The joint fit of the records `plant` gathered, and its row; `None`
    /// when the request asked for none or nothing was gathered.
    ///
    /// # Errors
    /// Why the joint fit failed, as [`Self::joint`].
    pub fn fit_plant(
        &self,
        plant: &Plant,
        progress: &dyn Progress,
    ) -> Option<Result<(JointOfRecords, RecordEstimate), RefineError>> {
        if plant.is_empty() {
            return None;
        }
        self.joint(&plant.records(), progress)
    }

    /// The joint estimate of every record of `plant` (a record and its
    /// row's estimate), the request's joint fit: their two-stage
    /// estimates pooled by their intervals (an estimate out of the
    /// estimator's distribution only starts the search), then one
    /// output-error fit of them all. `None` when the request asked for no
    /// joint fit.
    ///
    /// # Errors
    /// Why the joint fit failed: the caller keeps the records' own
    /// estimates.
    pub fn joint(
        &self,
        plant: &[(&IoData, &RecordEstimate)],
        progress: &dyn Progress,
    ) -> Option<Result<(JointOfRecords, RecordEstimate), RefineError>> {
        let fitter = self.joint.as_ref()?;
        let items: Vec<ToRefine<'_>> = plant
            .iter()
            .map(|(record, e)| {
                let widths = e
                    .half_widths
                    .as_deref()
                    .filter(|_| !e.out_of_distribution());
                (*record, e.theta.as_slice(), widths)
            })
            .collect();
        progress.begin_step("fitting jointly", 1, "plants");
        let found = fitter.fit(&items);
        progress.advance_step(1);
        progress.end_step();
        Some(found.map(|joint| {
            let q = joint.theta.len();
            let (widths, why) = match &joint.half_widths {
                Ok(w) => (w.clone(), None),
                Err(why) => (vec![f64::NAN; q], Some(why.clone())),
            };
            let row = RecordEstimate {
                half_widths: Some(widths),
                refinement: Some(RefineOutcome::Done(Refined {
                    by: RefinedBy::Descent {
                        stop: joint.stop,
                        optima: Some(SearchOptima {
                            count: joint.optima,
                            runner_up_over_best: joint.runner_up_ratio,
                        }),
                    },
                    interval_failure: why,
                    correlation: joint.correlation.clone(),
                })),
                ..RecordEstimate::bare(joint.theta.clone())
            };
            (joint, row)
        }))
    }
}

/// Refines the rows marked in `only` together: an output-error
/// refinement at each record's best fit from its search, a posterior
/// refinement by its own grid (their simulations in shared batches). A
/// refinement that fails keeps the two-stage estimate, and says why in
/// `refinement`; one that succeeds brings its own interval (NaN where the
/// record does not determine it, said in `interval_failure`).
pub(super) fn refine_together(
    refiner: &EstimateRefiner,
    rows: &mut [(String, RecordOutcome)],
    only: &[bool],
    searches: &[Search],
    progress: &dyn Progress,
) {
    let (items, bests): (Vec<ToRefine<'_>>, Vec<Result<BestFit, ModelFailure>>) = rows
        .iter()
        .zip(only)
        .zip(searches)
        .filter(|((_, only), _)| **only)
        .filter_map(|(((_, outcome), _), search)| {
            let (record, e) = outcome.as_ref().ok()?;
            let best = search.clone().unwrap_or(Err(ModelFailure::NoSearch));
            Some(((record, e.theta.as_slice(), e.half_widths.as_deref()), best))
        })
        .unzip();
    progress.begin_step("refining", items.len(), "records");
    let refined = if refiner.is_output_error() {
        let refined = refiner.refine_at(&items, &bests);
        progress.advance_step(items.len());
        refined
    } else {
        refiner.refine_many_reporting(&items, progress)
    };
    progress.end_step();
    let estimated = rows
        .iter_mut()
        .zip(only)
        .filter(|(_, only)| **only)
        .filter_map(|((_, outcome), _)| outcome.as_mut().ok());
    for ((_, e), result) in estimated.zip(refined) {
        match result {
            Ok(r) => {
                let q = r.theta.len();
                let (own, why) = match r.half_widths {
                    Ok(w) => (w, None),
                    Err(why) => (vec![f64::NAN; q], Some(why)),
                };
                e.theta = r.theta;
                e.half_widths = Some(own);
                e.refinement = Some(RefineOutcome::Done(Refined {
                    by: r.by,
                    interval_failure: why,
                    correlation: r.correlation,
                }));
            }
            Err(why) => e.refinement = Some(RefineOutcome::Failed(why)),
        }
    }
}

/// Checks one record's estimate against the record's best-fit search.
fn check(
    model: &dyn twostage_models::Simulator,
    record: &IoData,
    estimated: &RecordEstimate,
    search: &Search,
    estimating: &Estimating,
) -> Result<RecordCheck, ModelFailure> {
    let best = search
        .as_ref()
        .ok_or(ModelFailure::NoSearch)?
        .as_ref()
        .map_err(Clone::clone)?;
    check_against(model, record, &estimated.theta, best, estimating.plan)
        .map_err(ModelFailure::Check)
}
