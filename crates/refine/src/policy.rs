//! Which two-stage estimates a refinement takes on (`estimate
//! --refine=auto`): those the check does not explain, and those it could
//! call explained while they should not be trusted alone.

use crate::check::RecordCheck;

/// Why a record's two-stage estimate is refined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum RefineReason {
    /// The check does not explain the record at the estimate.
    NotExplained,
    /// The record's features lie outside the training's: the estimator
    /// extrapolates, whatever the check says of its estimate.
    OutOfDistribution,
    /// Some output is fitted worse than the policy's least fit.
    PoorFit,
    /// The record is of another length than the estimator was trained on.
    OtherLength,
}

impl RefineReason {
    /// The reason as messages write it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::NotExplained => "not explained",
            Self::OutOfDistribution => "out of distribution",
            Self::PoorFit => "fitted below the least fit",
            Self::OtherLength => "of another length than training's",
        }
    }
}

/// Which two-stage estimates to refine: a record the check does not
/// explain, out of distribution, fitted below `min_fit_percent` on some
/// output (even where the estimate is its search's best fit), or of
/// another length than training's.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `min_fit_percent` | 0 (the model at the estimate predicts worse than the record's mean) | any; `-inf` turns it off |
///
/// ```
/// use twostage_refine::{RefinePolicy, RefineReason};
/// let policy = RefinePolicy::default();
/// assert_eq!(policy.min_fit_percent, 0.0);
/// # use twostage_models::{experiment_rng, Benchmark, Simulator};
/// # let model = Benchmark::new();
/// # let mut record = model.spec().new_record();
/// # model.simulate(&[0.3], &mut experiment_rng(7, 0), &mut record)?;
/// # let check = twostage_refine::check_record(&model, &record, &[0.3], 99, 1)?;
/// // An explained record is still refined when out of distribution.
/// assert!(check.explained());
/// assert_eq!(policy.reason(&check, true, false), Some(RefineReason::OutOfDistribution));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinePolicy {
    /// The least fit (percent, per output) an estimate keeps unrefined.
    pub min_fit_percent: f64,
}

impl Default for RefinePolicy {
    fn default() -> Self {
        Self {
            min_fit_percent: 0.0,
        }
    }
}

impl RefinePolicy {
    /// Why the estimate `check` judged is refined (the first reason of
    /// [`RefineReason`]'s order), or `None` to keep it. A NaN fit (a
    /// constant record) is no reason.
    pub fn reason(
        &self,
        check: &RecordCheck,
        out_of_distribution: bool,
        other_length: bool,
    ) -> Option<RefineReason> {
        if !check.explained() {
            Some(RefineReason::NotExplained)
        } else if out_of_distribution {
            Some(RefineReason::OutOfDistribution)
        } else if check.fit_percent.iter().any(|f| *f < self.min_fit_percent) {
            Some(RefineReason::PoorFit)
        } else if other_length {
            Some(RefineReason::OtherLength)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use twostage_models::IoData;

    /// A check of one output with the given fit, tail probability (at the
    /// estimate and at its best fit) and loss over the best, whose best
    /// fit improves on the estimate as the model's noise would.
    fn judged(fit_percent: f64, tail_probability: f64, loss_ratio: f64) -> RecordCheck {
        RecordCheck {
            rms: vec![0.1],
            fit_percent: vec![fit_percent],
            tail_probability,
            improvement_tail_probability: 0.5,
            best_fit_tail_probability: tail_probability,
            reference_runs: 199,
            simulated: IoData::default(),
            input_differs_at: None,
            input_shared: false,
            loss_ratio,
            best_fit_percent: vec![fit_percent],
            best_theta: vec![0.0],
            optima: 1,
            runner_up_ratio: None,
        }
    }

    #[test]
    fn each_reason_refines_in_its_order() {
        let policy = RefinePolicy::default();
        // Explained by the model's noise and at its best fit: kept.
        let good = judged(90.0, 0.5, 1.0);
        assert_eq!(policy.reason(&good, false, false), None);
        // The model makes the record at its best fit, which improves on the
        // estimate by more than the noise would: not explained, though
        // within 1.1 of the best loss.
        let beaten = RecordCheck {
            improvement_tail_probability: 0.005,
            ..judged(90.0, 0.5, 1.05)
        };
        assert!(!beaten.explained() && !beaten.as_good_as_best_fit());
        assert_eq!(
            policy.reason(&beaten, false, false),
            Some(RefineReason::NotExplained)
        );
        // Not model-consistent, 1.2 times the best loss: not explained,
        // which comes before every other reason.
        let far = judged(90.0, 0.005, 1.2);
        assert!(!far.explained());
        assert_eq!(
            policy.reason(&far, true, true),
            Some(RefineReason::NotExplained)
        );
        // Within 1.1 of the best: explained, but refined when out of
        // distribution, when its fit is below the least, or of another
        // length.
        let near = judged(90.0, 0.005, 1.09);
        assert!(near.explained());
        assert_eq!(
            policy.reason(&near, true, true),
            Some(RefineReason::OutOfDistribution)
        );
        assert_eq!(
            policy.reason(&near, false, true),
            Some(RefineReason::OtherLength)
        );
        let poor = judged(-31.0, 0.005, 1.018);
        assert_eq!(
            policy.reason(&poor, false, false),
            Some(RefineReason::PoorFit)
        );
        // A stated least fit above it keeps the fit of 90% too; turned
        // off, a negative fit is no reason.
        let strict = RefinePolicy {
            min_fit_percent: 95.0,
        };
        assert_eq!(
            strict.reason(&near, false, false),
            Some(RefineReason::PoorFit)
        );
        let off = RefinePolicy {
            min_fit_percent: f64::NEG_INFINITY,
        };
        assert_eq!(off.reason(&poor, false, false), None);
        // A constant record's NaN fit is no reason.
        assert_eq!(
            policy.reason(&judged(f64::NAN, 0.5, 1.0), false, false),
            None
        );
    }
}
