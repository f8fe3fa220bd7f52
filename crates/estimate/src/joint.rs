//! One estimate of a plant from several of its records through an
//! estimator and its model, as the command line's `estimate --joint` and
//! the Python package's `Estimator.joint` both give it: the records'
//! two-stage estimates pooled, then one output-error fit of every record
//! on its own input ([`twostage_refine::JointEstimate`]).

use twostage_estimator::Estimator;
use twostage_fit::TerminationReason;
use twostage_models::{IoData, Simulator};
use twostage_refine::{
    BetweenRecords, JointPlan, OutputError, RefineError, Refinement, SearchStarts, SingleEstimate,
};

use crate::model_of::{EstimatorModel, SharedSimulator};
use crate::refiner::ToRefine;

/// One fitted record's whole parameter vector at a joint estimate: the
/// plant's parameters the joint estimate's, the record's own parameters
/// (`per_record = true` in the model file) its own.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOfJoint {
    /// The record's parameters.
    pub theta: Vec<f64>,
    /// Their interval half-widths at the estimator's level, where the
    /// joint estimate has an interval.
    pub half_widths: Option<Vec<f64>>,
    /// Their correlation matrix (row-major q x q), likewise.
    pub correlation: Option<Vec<f64>>,
}

/// The joint estimate of the records handed to [`JointFitter::fit`], each
/// record named by its place among them.
#[derive(Debug, Clone, PartialEq)]
pub struct JointOfRecords {
    /// The joint estimate (NaN at the records' own parameters, which have
    /// no one value: see `records`).
    pub theta: Vec<f64>,
    /// Its interval half-widths at the estimator's level, or why it has
    /// none (the records do not determine some parameter).
    pub half_widths: std::result::Result<Vec<f64>, RefineError>,
    /// Its correlation matrix (row-major q x q), where it has an interval.
    pub correlation: Option<Vec<f64>>,
    /// Why the best descent stopped.
    pub stop: TerminationReason,
    /// The distinct optima of the summed loss the search ended in.
    pub optima: usize,
    /// The second-best optimum's loss over the best's, with two or more.
    pub runner_up_ratio: Option<f64>,
    /// The two-stage estimates pooled by their intervals: the search's
    /// first start.
    pub pooled: Vec<f64>,
    /// The records fitted, by place, each with its fit (percent, its
    /// outputs' normalized fit averaged in squares) at the joint estimate.
    pub fitted: Vec<(usize, f64)>,
    /// The records left out, by place, with why.
    pub left_out: Vec<(usize, RefineError)>,
    /// The records whose two-stage estimate disagrees with the others'
    /// beyond its interval ([`twostage_refine::PooledEstimate`]), by
    /// place.
    pub disagreeing: Vec<usize>,
    /// How far the records' own best fits scatter about the joint
    /// estimate beyond their noise, where two or more determine every
    /// parameter: the joint interval includes it, and
    /// [`JointOfRecords::widen`] adds it to a record's own.
    pub between: Option<BetweenRecords>,
    /// The level `1 - alpha` of the intervals.
    pub alpha: f64,
    /// Per parameter, whether it belongs to each record rather than to
    /// the plant.
    pub per_record: Vec<bool>,
    /// Each fitted record's parameters at the joint estimate, in the
    /// order of `fitted`.
    pub records: Vec<RecordOfJoint>,
}

impl JointOfRecords {
    /// A record's interval half-widths with the scatter between the
    /// records added ([`BetweenRecords::widen`]): an interval of the
    /// plant's value, as the joint fit says its records are of one plant.
    /// Unchanged without a scatter.
    ///
    /// ```
    /// use twostage::JointOfRecords;
    /// use twostage::refine::{BetweenRecords, TerminationReason};
    /// let joint = JointOfRecords {
    ///     theta: vec![1.0], half_widths: Ok(vec![0.1]), correlation: None,
    ///     stop: TerminationReason::Converged, optima: 1, runner_up_ratio: None,
    ///     pooled: vec![1.0], fitted: vec![(0, 95.0), (1, 94.0)], left_out: vec![], disagreeing: vec![],
    ///     between: Some(BetweenRecords {
    ///         sd: vec![0.3], within_sd: vec![0.1], joint_sd: vec![0.2], beyond_chance: vec![true], records: 2,
    ///     }),
    ///     alpha: 0.1, per_record: vec![false], records: vec![],
    /// };
    /// let widened = joint.widen(&[0.2]);
    /// assert!((widened[0] - 0.2f64.hypot(1.6448536269514722 * 0.3)).abs() < 1e-9);
    /// ```
    pub fn widen(&self, half_widths: &[f64]) -> Vec<f64> {
        match &self.between {
            Some(between) => between.widen(half_widths, self.alpha),
            None => half_widths.to_vec(),
        }
    }

    /// Whether some parameter belongs to each record: then each fitted
    /// record has its own whole estimate in `records`, and `theta` none.
    pub fn has_own_parameters(&self) -> bool {
        self.per_record.contains(&true)
    }
}

/// Joint estimates of an estimator's plant: see [`JointFitter::new`].
pub struct JointFitter {
    fit: Refinement<OutputError<SharedSimulator>>,
    plan: JointPlan,
    per_record: Vec<bool>,
}

impl JointFitter {
    /// Joint estimates through `estimator`'s `model` by output error,
    /// starting from `search`'s starts
    /// over the prior besides the records' own estimates, the interval at
    /// the estimator's level (90% without intervals).
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::{Benchmark, Simulator, experiment_rng};
    /// use twostage::refine::SearchStarts;
    /// use twostage::{EstimatorModel, JointFitter};
    /// let model = Benchmark::new();
    /// let estimator = TwoStage::builder(&model)
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(400).validation(0).calibration(200).seed(3).train()?;
    /// let records: Vec<_> = (0..3).map(|i| {
    ///     let mut record = model.spec().new_record();
    ///     model.simulate(&[0.3], &mut experiment_rng(8, i), &mut record).map(|_| record)
    /// }).collect::<Result<_, _>>()?;
    /// let singles: Vec<_> = records.iter()
    ///     .map(|r| estimator.assess(r).map(|a| (a.theta.clone(), a.interval_half_widths().map(<[f64]>::to_vec))))
    ///     .collect::<Result<_, _>>()?;
    /// let items: Vec<_> = records.iter().zip(&singles)
    ///     .map(|(r, (t, w))| (r, t.as_slice(), w.as_deref())).collect();
    /// let fitter = JointFitter::new(&estimator, &EstimatorModel::find(&estimator, None)?, SearchStarts { from_prior: 4, seed: 0 })?;
    /// let joint = fitter.fit(&items)?;
    /// assert_eq!(joint.fitted.len(), 3);
    /// assert!((joint.theta[0] - 0.3).abs() < 0.2);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// A model that cannot be built or run without noise on a given
    /// input.
    pub fn new(
        estimator: &Estimator,
        model: &EstimatorModel<'_>,
        search: SearchStarts,
    ) -> twostage_train::Result<Self> {
        let fit = OutputError::new(model.simulator()?)?;
        let alpha = estimator.intervals().map_or(0.1, |i| i.alpha());
        let per_record = fit.simulator().spec().per_record().to_vec();
        Ok(Self {
            fit: Refinement::new(fit),
            plan: JointPlan { search, alpha },
            per_record,
        })
    }

    /// The simulator the fit runs.
    pub fn simulator(&self) -> &dyn Simulator {
        self.fit.model().simulator().as_ref()
    }

    /// The joint estimate of `items` (each record with its two-stage
    /// estimate and, where it has one, its interval).
    ///
    /// # Errors
    /// No record, or a model that runs on none of them (the first
    /// record's reason).
    pub fn fit(&self, items: &[ToRefine<'_>]) -> std::result::Result<JointOfRecords, RefineError> {
        let singles: Vec<SingleEstimate<'_>> = items
            .iter()
            .map(|(record, theta, half_widths)| SingleEstimate {
                record,
                theta,
                half_widths: *half_widths,
            })
            .collect();
        let joint = self
            .fit
            .joint_estimate_with_own(&singles, self.plan, &self.per_record)?;
        let fits: Vec<f64> = match &joint.record_losses {
            Some(losses) => joint
                .fitted
                .iter()
                .zip(losses)
                .map(|(&i, loss)| normalized_fit(items[i].0, *loss))
                .collect(),
            None => vec![f64::NAN; joint.fitted.len()],
        };
        Ok(JointOfRecords {
            half_widths: joint
                .uncertainty
                .as_ref()
                .map(|u| u.half_widths(self.plan.alpha))
                .map_err(Clone::clone),
            correlation: joint
                .uncertainty
                .as_ref()
                .ok()
                .map(|u| u.correlation.clone()),
            stop: joint.search.best.stop,
            optima: joint.search.optima.len(),
            runner_up_ratio: joint.search.runner_up_ratio(),
            theta: joint.theta,
            pooled: joint.pooled.theta,
            fitted: joint.fitted.into_iter().zip(fits).collect(),
            left_out: joint.left_out,
            disagreeing: joint.pooled.disagreeing,
            between: joint.between,
            alpha: self.plan.alpha,
            per_record: self.per_record.clone(),
            records: joint
                .records_theta
                .into_iter()
                .enumerate()
                .map(|(r, theta)| {
                    let local = joint.records_uncertainty.as_ref().map(|u| &u[r]);
                    RecordOfJoint {
                        theta,
                        half_widths: local.map(|u| u.half_widths(self.plan.alpha)),
                        correlation: local.map(|u| u.correlation.clone()),
                    }
                })
                .collect(),
        })
    }
}

/// The normalized fit (percent) of a record whose output errors, each
/// output scaled by its own spread, sum in squares to `loss`: the
/// outputs' `100 (1 - rms)` averaged in squares.
fn normalized_fit(record: &IoData, loss: f64) -> f64 {
    let n = (record.n_samples() * record.n_outputs()).max(1) as f64;
    100.0 * (1.0 - (loss / n).sqrt())
}
