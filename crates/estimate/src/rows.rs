//! What an estimate request gives back: a typed row per record (or
//! window), and which records `refine = auto` chose.

use twostage_compress::FlooredSample;
use twostage_estimator::interval_in_box;

use twostage_models::{InputDeviation, IoData};
use twostage_refine::{RecordCheck, RefineError, RefineReason};

use super::failure::RecordFailure;
use crate::{ModelFailure, PosteriorDraws, RefinedBy, SearchOptima};

/// One record's (or window's) estimate and what was found about it.
#[derive(Debug, Clone)]
pub struct RecordEstimate {
    /// The estimate (refined, where a refinement succeeded).
    pub theta: Vec<f64>,
    /// Its interval's half-widths, where known: an estimator's adaptive
    /// ones where calibrated, else its conformal ones; a refined
    /// estimate's own (NaN where the record does not determine it).
    pub half_widths: Option<Vec<f64>>,
    /// The record's feature distance and the out-of-distribution
    /// threshold, where the estimator has a feature envelope.
    pub distance: Option<(f64, f64)>,
    /// How the record's input lies outside the estimator's input family
    /// (empty inside it), when the estimator knows one.
    pub input: Option<Vec<InputDeviation>>,
    /// The distance of the record's input shape from the held-out
    /// records' and the threshold 99% of theirs stay within, when the
    /// estimator knows their shapes.
    pub input_shape: Option<(f64, f64)>,
    /// Samples outside their output's transform, when the estimator
    /// transforms its outputs.
    pub floored: Option<Vec<FlooredSample>>,
    /// With a check: how the model at the estimate explains the record, or
    /// why it could not be simulated.
    pub check: Option<Result<RecordCheck, ModelFailure>>,
    /// What was done after the estimate: nothing (`None`), a refinement
    /// (or the output-error method, or the joint fit) and how it ended,
    /// or why it failed (the two-stage estimate is kept).
    pub refinement: Option<RefineOutcome>,
    /// With windows: the window's last sample in its record, from 1.
    pub window_end: Option<usize>,
    /// With samples asked: the draws from the estimator's posterior given
    /// the record.
    pub posterior: Option<PosteriorDraws>,
}

impl RecordEstimate {
    /// An estimate that is nothing but its parameters.
    ///
    /// ```
    /// let row = twostage::RecordEstimate::bare(vec![0.3]);
    /// assert!(!row.out_of_distribution() && row.in_family().is_none());
    /// ```
    pub fn bare(theta: Vec<f64>) -> Self {
        Self {
            theta,
            half_widths: None,
            distance: None,
            input: None,
            input_shape: None,
            floored: None,
            check: None,
            refinement: None,
            window_end: None,
            posterior: None,
        }
    }

    /// The refined estimate, where a refinement succeeded.
    pub fn refined(&self) -> Option<&Refined> {
        match &self.refinement {
            Some(RefineOutcome::Done(refined)) => Some(refined),
            _ => None,
        }
    }

    /// The estimate's correlation matrix (row-major q x q), where it has
    /// one: a refined estimate's, or the posterior draws'.
    pub fn correlation(&self) -> Option<&[f64]> {
        match (self.refined(), &self.posterior) {
            (Some(refined), _) => refined.correlation.as_deref(),
            (None, Some(draws)) => Some(draws.correlation()),
            (None, None) => None,
        }
    }

    /// Of an output-error search (a refinement's, or the joint fit's): the
    /// distinct optima it ended in, and the runner-up's loss over the
    /// best's.
    pub fn optima(&self) -> Option<SearchOptima> {
        match self.refined()?.by {
            RefinedBy::Descent { optima, .. } => optima,
            RefinedBy::PosteriorMean => None,
        }
    }

    /// Whether the record's input lies in the estimator's input family,
    /// by its summary's ranges and by its shape (`None` when it knows
    /// none).
    pub fn in_family(&self) -> Option<bool> {
        self.input
            .as_ref()
            .map(|d| d.is_empty() && !self.input_shape_outside())
    }

    /// Whether the record's input is of a shape the held-out records'
    /// inputs did not have.
    pub fn input_shape_outside(&self) -> bool {
        self.input_shape.is_some_and(|(d, t)| d > t || d.is_nan())
    }

    /// The interval as written: `theta +- half_widths`, inside the
    /// prior's box where known (a parameter's interval never leaves its
    /// prior's support); `None` without half-widths.
    ///
    /// ```
    /// let row = twostage::RecordEstimate {
    ///     half_widths: Some(vec![0.2]),
    ///     ..twostage::RecordEstimate::bare(vec![0.8])
    /// };
    /// let (lower, upper) = row.interval(Some((&[-0.9], &[0.9]))).unwrap();
    /// assert!((lower[0] - 0.6).abs() < 1e-12 && upper[0] == 0.9);
    /// ```
    pub fn interval(&self, prior_box: Option<(&[f64], &[f64])>) -> Option<(Vec<f64>, Vec<f64>)> {
        let widths = self.half_widths.as_ref()?;
        Some(match prior_box {
            Some((lower, upper)) => interval_in_box(&self.theta, widths, lower, upper),
            None => self
                .theta
                .iter()
                .zip(widths)
                .map(|(t, w)| (t - w, t + w))
                .unzip(),
        })
    }

    /// Outside what training saw, by the features or by the input (its
    /// summary or its shape).
    pub fn out_of_distribution(&self) -> bool {
        self.distance.is_some_and(|(d, t)| d > t)
            || self.input.as_ref().is_some_and(|d| !d.is_empty())
            || self.input_shape_outside()
    }
}

/// What a refinement of one row came to.
#[derive(Debug, Clone)]
pub enum RefineOutcome {
    /// It failed, and why: the row keeps its estimate.
    Failed(ModelFailure),
    /// It gave the row's estimate.
    Done(Refined),
}

/// A refined estimate: how it was found, and its own interval's fate.
#[derive(Debug, Clone)]
pub struct Refined {
    /// A posterior mean, or where an output-error descent stopped.
    pub by: RefinedBy,
    /// Why the refined estimate has no interval of its own (its
    /// half-widths are then NaN): the record does not determine some
    /// parameter. `None` where it has one, or where nothing computes one
    /// (the output-error method).
    pub interval_failure: Option<RefineError>,
    /// The refined parameters' correlation matrix (row-major q x q),
    /// where the interval has one.
    pub correlation: Option<Vec<f64>>,
}

/// A record (or window) with its estimate, or why it has none.
pub type RecordOutcome = Result<(IoData, RecordEstimate), RecordFailure>;

/// The estimates of one batch of records, in their order.
#[derive(Debug)]
pub struct Estimates {
    /// Each record's (or window's) experiment id and outcome.
    pub rows: Vec<(String, RecordOutcome)>,
    /// With `RefineWhich::Auto`: what the check chose.
    pub auto: Option<AutoRefined>,
}

/// Which records `RefineWhich::Auto` refined, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoRefined {
    /// Two-stage estimates the check explained.
    pub explained: usize,
    /// Records (or windows) checked.
    pub checked: usize,
    /// Why each row was refined (`None`: it kept its estimate), in the
    /// rows' order.
    pub reasons: Vec<Option<RefineReason>>,
}

impl AutoRefined {
    /// The refined rows' ids grouped by reason, in the order the reasons
    /// first occur.
    pub fn groups<'a>(
        &self,
        rows: &'a [(String, RecordOutcome)],
    ) -> Vec<(RefineReason, Vec<&'a str>)> {
        let mut groups: Vec<(RefineReason, Vec<&str>)> = Vec::new();
        for ((id, _), reason) in rows.iter().zip(&self.reasons) {
            let Some(reason) = reason else { continue };
            match groups.iter_mut().find(|(r, _)| r == reason) {
                Some((_, ids)) => ids.push(id),
                None => groups.push((*reason, vec![id])),
            }
        }
        groups
    }
}

/// The records of one plant gathered over batches for the request's
/// joint fit ([`Estimating::fit_plant`](super::Estimating::fit_plant)):
/// each record a batch estimated, with its estimate and its place. Empty,
/// and gathering nothing, when the request asked for no joint fit.
#[derive(Debug, Clone, Default)]
pub struct Plant {
    joins: bool,
    records: Vec<(String, IoData, RecordEstimate)>,
}

impl Plant {
    pub(super) fn new(joins: bool) -> Self {
        Self {
            joins,
            records: Vec::new(),
        }
    }

    /// Every estimated row of `estimates` (the failed ones left out),
    /// named by `place` of its id (`file.csv: experiment 3`, say).
    pub fn gather(&mut self, estimates: &Estimates, place: impl Fn(&str) -> String) {
        if !self.joins {
            return;
        }
        for (id, outcome) in &estimates.rows {
            if let Ok((record, row)) = outcome {
                self.records.push((place(id), record.clone(), row.clone()));
            }
        }
    }

    /// The gathered records' places, in the order gathered: a joint fit's
    /// record indices point here.
    pub fn places(&self) -> Vec<&str> {
        self.records.iter().map(|(p, _, _)| p.as_str()).collect()
    }

    /// How many records are gathered.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// Whether none is.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    pub(super) fn records(&self) -> Vec<(&IoData, &RecordEstimate)> {
        self.records.iter().map(|(_, r, e)| (r, e)).collect()
    }
}
