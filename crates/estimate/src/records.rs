//! The request's run over its records: each estimated (whole, or window
//! by window), then checked and refined as the request asked.

use rayon::prelude::*;
use twostage_models::IoData;
use twostage_refine::RefineReason;
use twostage_sources::Progress;
use twostage_sources::csv_rows::DataFileError;

use super::failure::RecordFailure;
use super::rows::{AutoRefined, Estimates, RecordEstimate, RecordOutcome};
use super::{Estimating, RefineWhich};

impl Estimating {
    /// Estimates `records` (each an experiment id and its record, or why
    /// it could not be read, kept as it is), in parallel, in their order;
    /// with windows, each window of a record as a row of its own. Then
    /// checks and refines them as the request asked: one best-fit search
    /// per record serves its check and its output-error refinement; with
    /// `RefineWhich::Auto` the estimates are checked first and only those
    /// the policy names are refined (and checked again). A record's error
    /// names `source` (its file, say) and its experiment. Reports its
    /// steps to `progress`.
    pub fn estimate(
        &self,
        source: &str,
        records: Vec<(String, Result<IoData, DataFileError>)>,
        progress: &dyn Progress,
    ) -> Estimates {
        self.estimate_each(
            records,
            &|id| format!("{source}: experiment {id}"),
            progress,
        )
    }

    /// [`Estimating::estimate`], a record's error named by `place` of its
    /// id (`records[3]`, say) instead of a source and an experiment.
    pub fn estimate_each(
        &self,
        records: Vec<(String, Result<IoData, DataFileError>)>,
        place: &(dyn Fn(&str) -> String + Sync),
        progress: &dyn Progress,
    ) -> Estimates {
        let pieces = self.pieces(records, place);
        progress.begin_step("estimating", pieces.len(), "records");
        let mut rows: Vec<(String, RecordOutcome)> = pieces
            .into_par_iter()
            .enumerate()
            .map(|(index, (id, record, window_end))| {
                let estimated = record.and_then(|record| {
                    let failed = |why| RecordFailure::NotEstimated {
                        place: place(&id),
                        why,
                    };
                    let estimated = self.method.estimate(&id, &record).map_err(failed)?;
                    let posterior = self.draws(&id, &record, index).map_err(failed)?;
                    Ok((
                        record,
                        RecordEstimate {
                            window_end,
                            posterior,
                            ..estimated
                        },
                    ))
                });
                progress.advance_step(1);
                (id, estimated)
            })
            .collect();
        progress.end_step();
        self.sharpen(&mut rows, place, progress);
        let auto = self.check_and_refine(&mut rows, progress);
        Estimates { rows, auto }
    }

    /// The draws asked of the `index`th record (or window) of a batch, the
    /// experiment `id`, where samples are asked; with the level of its
    /// posterior's region that holds the values given for it.
    fn draws(
        &self,
        id: &str,
        record: &IoData,
        index: usize,
    ) -> Result<Option<crate::PosteriorDraws>, crate::MethodFailure> {
        let (Some(samples), super::methods::Method::TwoStage { estimator, .. }) =
            (self.samples, &self.method)
        else {
            return Ok(None);
        };
        let at = self.region.as_ref().map(|v| v.of(id)).transpose()?;
        Ok(Some(super::draws::draw(
            estimator,
            record,
            samples,
            (self.plan.seed, index),
            at.as_deref(),
        )?))
    }

    /// The records to estimate: each whole, or with windows each of its
    /// windows (its last sample, from 1, beside it). A record shorter than
    /// one window is refused by name.
    #[allow(clippy::type_complexity)]
    fn pieces(
        &self,
        records: Vec<(String, Result<IoData, DataFileError>)>,
        place: &(dyn Fn(&str) -> String + Sync),
    ) -> Vec<(String, Result<IoData, RecordFailure>, Option<usize>)> {
        let Some(windows) = self.windows else {
            return records
                .into_iter()
                .map(|(id, r)| (id, r.map_err(RecordFailure::from), None))
                .collect();
        };
        let mut pieces = Vec::new();
        for (id, record) in records {
            let record = match record {
                Ok(record) => record,
                Err(e) => {
                    pieces.push((id, Err(e.into()), None));
                    continue;
                }
            };
            match windows.ends(record.n_samples(), &place(&id)) {
                Err(why) => pieces.push((id, Err(why), None)),
                Ok(ends) => {
                    for end in ends {
                        let start = end - windows.length;
                        pieces.push((id.clone(), Ok(record.window(start, end)), Some(end)));
                    }
                }
            }
        }
        pieces
    }

    /// The rows checked and refined as the request asked; what
    /// `RefineWhich::Auto` chose.
    fn check_and_refine(
        &self,
        rows: &mut [(String, RecordOutcome)],
        progress: &dyn Progress,
    ) -> Option<AutoRefined> {
        let everyone = vec![true; rows.len()];
        let searches = self.search(rows, progress);
        match (&self.refiner, self.refine) {
            (Some(refiner), Some(RefineWhich::Auto(_))) => {
                self.check_all(rows, &everyone, &searches, progress);
                let reasons: Vec<Option<RefineReason>> = rows
                    .iter()
                    .map(|(_, outcome)| {
                        let (record, e) = outcome.as_ref().ok()?;
                        self.reason(record, e)
                    })
                    .collect();
                let chosen: Vec<bool> = reasons.iter().map(Option::is_some).collect();
                let explained = rows
                    .iter()
                    .filter(|(_, outcome)| {
                        matches!(outcome, Ok((_, e)) if matches!(&e.check, Some(Ok(c)) if c.explained()))
                    })
                    .count();
                super::through_model::refine_together(refiner, rows, &chosen, &searches, progress);
                self.check_all(rows, &chosen, &searches, progress);
                self.settle_on_best_fits(rows, &chosen, &searches);
                Some(AutoRefined {
                    explained,
                    checked: everyone.len(),
                    reasons,
                })
            }
            (Some(refiner), _) => {
                super::through_model::refine_together(
                    refiner, rows, &everyone, &searches, progress,
                );
                self.check_all(rows, &everyone, &searches, progress);
                self.settle_on_best_fits(rows, &everyone, &searches);
                None
            }
            (None, _) => {
                self.check_all(rows, &everyone, &searches, progress);
                None
            }
        }
    }
}
