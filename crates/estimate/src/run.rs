//! The whole run of a request over its records: batch after batch (a
//! file's records, or records in memory), each estimated as the request
//! asked, then the joint estimate of every record estimated, so that no
//! door gathers records for the joint fit itself.

use twostage_models::IoData;
use twostage_refine::RefineError;
use twostage_sources::Progress;
use twostage_sources::csv_rows::DataFileError;
use twostage_sources::record_file;

use super::Estimating;
use super::rows::{Estimates, RecordEstimate, RefineOutcome};
use crate::JointOfRecords;

/// How a batch names one of its records in errors and in the joint fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordPlace {
    /// `SOURCE: experiment ID` (a file's records).
    Experiment,
    /// `SOURCE[ID]` (records given as a list).
    Indexed,
}

/// Records to estimate together, with where they came from.
pub struct RecordBatch {
    /// Where they came from: a file's path, or a name such as `records`.
    pub source: String,
    /// Each record's experiment and the record, or why it could not be
    /// read (kept as it is: its row says why).
    pub records: Vec<(String, Result<IoData, DataFileError>)>,
    /// How a record is named.
    pub place: RecordPlace,
}

impl RecordBatch {
    /// A batch of records in memory, named `source[ID]` where they are
    /// named.
    pub fn indexed(source: &str, records: Vec<(String, IoData)>) -> Self {
        Self {
            source: source.to_string(),
            records: records.into_iter().map(|(id, r)| (id, Ok(r))).collect(),
            place: RecordPlace::Indexed,
        }
    }
}

fn place(source: &str, how: RecordPlace, id: &str) -> String {
    match how {
        RecordPlace::Experiment => format!("{source}: experiment {id}"),
        RecordPlace::Indexed => format!("{source}[{id}]"),
    }
}

/// The joint estimate of a run's records.
pub struct JointRun {
    /// Each record fitted, by place, in the order the joint fit's record
    /// indices count.
    pub places: Vec<String>,
    /// The joint fit and its row, or why it failed (the records keep
    /// their own estimates).
    pub fit: Result<(JointOfRecords, RecordEstimate), RefineError>,
}

impl JointRun {
    /// The joint fit's rows, to follow the records' own: one row `joint`,
    /// or, where some parameter belongs to each record (`per_record =
    /// true` in the model file), one row `joint[K]` per fitted record (`K`
    /// its place in [`JointRun::places`]) with its whole estimate, the
    /// plant's parameters the joint ones and its own its own.
    ///
    /// # Errors
    /// Why the joint fit failed.
    pub fn rows(&self) -> Result<Vec<(String, RecordEstimate)>, &RefineError> {
        let (joint, row) = self.fit.as_ref()?;
        if !joint.has_own_parameters() {
            return Ok(vec![("joint".into(), row.clone())]);
        }
        Ok(joint
            .fitted
            .iter()
            .zip(&joint.records)
            .map(|((place, _), own)| {
                let mut mine = row.clone();
                mine.theta.clone_from(&own.theta);
                mine.half_widths = Some(
                    own.half_widths
                        .clone()
                        .unwrap_or_else(|| vec![f64::NAN; own.theta.len()]),
                );
                if let Some(RefineOutcome::Done(refined)) = &mut mine.refinement {
                    refined.correlation.clone_from(&own.correlation);
                }
                (format!("joint[{place}]"), mine)
            })
            .collect())
    }

    /// The rows of the records gathered, in [`JointRun::places`]' order
    /// (the rows `each` was handed, the failed ones left out), each
    /// interval widened by the scatter between the records
    /// ([`JointOfRecords::widen`]); nothing changes where the joint fit
    /// failed or found no scatter.
    pub fn widen<'a>(&self, rows: impl IntoIterator<Item = &'a mut RecordEstimate>) {
        let Ok((joint, _)) = &self.fit else { return };
        for row in rows.into_iter().take(self.places.len()) {
            if let Some(widths) = &mut row.half_widths {
                *widths = joint.widen(widths);
            }
        }
    }
}

impl Estimating {
    /// The records of the record file at `path`, laid out as the request's
    /// records are ([`Estimating::record_format`]), named `PATH:
    /// experiment ID`.
    ///
    /// # Errors
    /// The file cannot be read as records at all (a record that cannot
    /// be is kept, with why, in the batch).
    pub fn read_file(&self, path: &std::path::Path) -> Result<RecordBatch, DataFileError> {
        let reads = record_file::read(path, &self.record_format())?;
        Ok(RecordBatch {
            source: path.display().to_string(),
            records: reads.into_iter().map(|r| (r.id, r.record)).collect(),
            place: RecordPlace::Experiment,
        })
    }

    /// The request's whole run: each batch estimated in turn and handed
    /// to `each` with its source (a door prints or converts it there),
    /// then, where the request asked, the joint estimate of every record
    /// estimated. A batch that cannot be had, or an `each` that fails,
    /// ends the run with its error.
    ///
    /// ```
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::{EstimateRequest, EstimateWith, RecordBatch, Silent, TwoStage};
    /// let model = Benchmark::new();
    /// let estimator = TwoStage::builder(&model)
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(300).validation(0).calibration(150).seed(3).train()?;
    /// let records: Vec<_> = (0..2u64).map(|i| {
    ///     let mut record = model.spec().new_record();
    ///     model.simulate(&[0.3], &mut experiment_rng(9, i), &mut record).map(|()| (i.to_string(), record))
    /// }).collect::<Result<_, _>>()?;
    /// let estimating = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator)))
    ///     .joint(true)
    ///     .prepare()?;
    /// let mut rows = 0;
    /// let joint = estimating.run(
    ///     [Ok::<_, String>(RecordBatch::indexed("records", records))],
    ///     &Silent,
    ///     |_, estimates| { rows += estimates.rows.len(); Ok(()) },
    /// )?;
    /// let joint = joint.expect("asked for");
    /// assert_eq!((rows, joint.places), (2, vec!["records[0]".to_string(), "records[1]".into()]));
    /// let (_, row) = joint.fit.map_err(|e| e.to_string())?;
    /// assert!((row.theta[0] - 0.3).abs() < 0.05);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// The first batch's or `each`'s error.
    pub fn run<E>(
        &self,
        batches: impl IntoIterator<Item = Result<RecordBatch, E>>,
        progress: &dyn Progress,
        mut each: impl FnMut(&str, Estimates) -> Result<(), E>,
    ) -> Result<Option<JointRun>, E> {
        let mut plant = self.plant();
        for batch in batches {
            let RecordBatch {
                source,
                records,
                place: how,
            } = batch?;
            let estimates = self.estimate_each(records, &|id| place(&source, how, id), progress);
            plant.gather(&estimates, |id| place(&source, how, id));
            each(&source, estimates)?;
        }
        Ok(self.fit_plant(&plant, progress).map(|fit| JointRun {
            places: plant.places().into_iter().map(str::to_string).collect(),
            fit,
        }))
    }
}
