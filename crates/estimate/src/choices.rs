//! What a request asks besides its way of estimating: values given for
//! the records, which estimates to refine, windows of each record, and how
//! a check ranks a record.

use std::collections::HashMap;

use twostage_models::ModelSpec;
use twostage_refine::{DEFAULT_CHECK_RUNS, RefinePolicy};

use crate::{GivenValuesError, RecordFailure, RequestProblem};

/// Values given for the records: one row for every record, or a row per
/// experiment.
#[derive(Debug, Clone)]
pub struct GivenValues {
    /// A single row, which stands for every record: its experiment and
    /// values.
    one: Option<(String, Vec<f64>)>,
    by_id: HashMap<String, Vec<f64>>,
    /// Where they came from, for the message of a record without a row.
    from: String,
}

/// The first of `rows` (experiment, values) read from `from` whose values
/// lie outside `spec`'s prior box, said as the estimate request refuses
/// it (`None`: all inside); `simulate --at` asks it too.
///
/// ```
/// use twostage::values_outside_prior;
/// use twostage::models::{Benchmark, Simulator};
/// let spec = Benchmark::new().spec().clone();
/// let (a, b) = (vec![0.5], vec![1.5]);
/// assert!(values_outside_prior("v.csv", [("a", &a)], &spec).is_none());
/// let outside = values_outside_prior("v.csv", [("a", &a), ("b", &b)], &spec).expect("b");
/// assert!(outside.to_string().starts_with("v.csv, experiment b: "), "{outside}");
/// ```
pub fn values_outside_prior<'a>(
    from: &str,
    rows: impl IntoIterator<Item = (&'a str, &'a Vec<f64>)>,
    spec: &ModelSpec,
) -> Option<RequestProblem> {
    rows.into_iter().find_map(|(id, theta)| {
        spec.prior()
            .check(theta, spec.param_names(), false)
            .err()
            .map(|why| RequestProblem::OutsidePrior {
                from: from.to_string(),
                id: id.to_string(),
                why: why.to_string(),
            })
    })
}

impl GivenValues {
    /// The first row (by experiment) whose values lie outside `spec`'s
    /// prior box, as [`values_outside_prior`] says it.
    ///
    /// ```
    /// use twostage::{GivenValues, RequestProblem};
    /// use twostage::models::{Benchmark, Simulator};
    /// let spec = Benchmark::new().spec().clone();
    /// let inside = GivenValues::new(vec![("a".into(), vec![0.5])], "v.csv")?;
    /// assert!(inside.outside_prior(&spec).is_none());
    /// let rows = vec![("a".into(), vec![0.5]), ("b".into(), vec![1.5])];
    /// let outside = GivenValues::new(rows, "v.csv")?.outside_prior(&spec).expect("b is outside");
    /// assert!(outside.to_string().starts_with("v.csv, experiment b: "), "{outside}");
    /// # Ok::<(), twostage::GivenValuesError>(())
    /// ```
    pub fn outside_prior(&self, spec: &ModelSpec) -> Option<RequestProblem> {
        let mut rows: Vec<(&str, &Vec<f64>)> = self
            .one
            .iter()
            .map(|(id, theta)| (id.as_str(), theta))
            .chain(self.by_id.iter().map(|(id, theta)| (id.as_str(), theta)))
            .collect();
        rows.sort_by(|a, b| a.0.cmp(b.0));
        values_outside_prior(&self.from, rows, spec)
    }

    /// The `rows` (experiment, values) read from `from`: a single row
    /// stands for every record.
    ///
    /// ```
    /// use twostage::{GivenValues, GivenValuesError};
    /// let given = GivenValues::new(
    ///     vec![("1".into(), vec![0.2]), ("2".into(), vec![0.4])],
    ///     "values.csv",
    /// )?;
    /// assert_eq!(given.of("2")?, vec![0.4]);
    /// let missing = given.of("3").unwrap_err();
    /// assert!(matches!(&missing, GivenValuesError::NoRow { id, .. } if id == "3"));
    /// assert!(missing.to_string().contains("values.csv has no row for experiment 3"));
    /// # Ok::<(), GivenValuesError>(())
    /// ```
    ///
    /// # Errors
    /// Two rows of one experiment ([`GivenValuesError::TwoRows`]).
    pub fn new(rows: Vec<(String, Vec<f64>)>, from: &str) -> Result<Self, GivenValuesError> {
        let mut given = Self {
            one: None,
            by_id: HashMap::new(),
            from: from.to_string(),
        };
        if let [(id, theta)] = rows.as_slice() {
            given.one = Some((id.clone(), theta.clone()));
            return Ok(given);
        }
        for (id, theta) in rows {
            if given.by_id.contains_key(&id) {
                return Err(GivenValuesError::TwoRows {
                    from: from.to_string(),
                    id,
                });
            }
            given.by_id.insert(id, theta);
        }
        Ok(given)
    }

    /// How many values each row holds.
    pub(crate) fn widths(&self) -> impl Iterator<Item = usize> + '_ {
        self.one
            .iter()
            .map(|(_, theta)| theta.len())
            .chain(self.by_id.values().map(Vec::len))
    }

    /// The values of experiment `id`.
    ///
    /// # Errors
    /// No row for it, and more than one row in all
    /// ([`GivenValuesError::NoRow`]).
    pub fn of(&self, id: &str) -> Result<Vec<f64>, GivenValuesError> {
        match &self.one {
            Some((_, theta)) => Ok(theta.clone()),
            None => self
                .by_id
                .get(id)
                .cloned()
                .ok_or_else(|| GivenValuesError::NoRow {
                    from: self.from.clone(),
                    id: id.to_string(),
                }),
        }
    }
}

/// Which estimates a request refines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RefineWhich {
    /// Every record's.
    All,
    /// Those the check does not explain, or that the policy names
    /// otherwise (a poor fit, out of distribution, another length); every
    /// record is checked to choose.
    Auto(RefinePolicy),
}

impl RefineWhich {
    /// Whether records refined this way are checked first: `auto` checks
    /// every record to choose which to refine (the one place the rule is
    /// written; a request and a door's refusals both read it).
    ///
    /// ```
    /// use twostage::RefineWhich;
    /// assert!(!RefineWhich::All.checks());
    /// assert!(RefineWhich::chosen(Some("auto"), None).unwrap().unwrap().checks());
    /// ```
    pub fn checks(self) -> bool {
        matches!(self, Self::Auto(_))
    }

    /// The refinement a door names: `which` is `"all"` or `"auto"` (none:
    /// no refinement), and `below_fit` the fit in percent below which
    /// `"auto"` refines a record however well the check explains it
    /// (default [`RefinePolicy::default`]). Every door reads its choice
    /// here, so a threshold given without `"auto"` is refused the same way
    /// through each.
    ///
    /// ```
    /// use twostage::{RefineChoiceError, RefineWhich};
    /// assert_eq!(RefineWhich::chosen(Some("all"), None), Ok(Some(RefineWhich::All)));
    /// let Ok(Some(RefineWhich::Auto(policy))) = RefineWhich::chosen(Some("auto"), Some(5.0)) else {
    ///     panic!("auto with a threshold");
    /// };
    /// assert_eq!(policy.min_fit_percent, 5.0);
    /// assert_eq!(
    ///     RefineWhich::chosen(Some("all"), Some(5.0)),
    ///     Err(RefineChoiceError::BelowFitWithoutAuto)
    /// );
    /// assert_eq!(RefineWhich::chosen(None, None), Ok(None));
    /// ```
    pub fn chosen(
        which: Option<&str>,
        below_fit: Option<f64>,
    ) -> Result<Option<RefineWhich>, RefineChoiceError> {
        let chosen = match which {
            None => None,
            Some("all") => Some(RefineWhich::All),
            Some("auto") => Some(RefineWhich::Auto(RefinePolicy {
                min_fit_percent: below_fit.unwrap_or(RefinePolicy::default().min_fit_percent),
            })),
            Some(other) => return Err(RefineChoiceError::Unknown(other.to_string())),
        };
        if below_fit.is_some() && !matches!(chosen, Some(RefineWhich::Auto(_))) {
            return Err(RefineChoiceError::BelowFitWithoutAuto);
        }
        Ok(chosen)
    }
}

/// A refinement choice [`RefineWhich::chosen`] refuses; each door says it
/// in the words of its own flags.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RefineChoiceError {
    /// Neither `all` nor `auto`.
    #[error("refine {0:?}: give all or auto")]
    Unknown(String),
    /// A fit threshold without `auto`, which alone reads it.
    #[error(
        "the fit below which to refine is read when refining auto only: leave it out or refine auto"
    )]
    BelowFitWithoutAuto,
}

/// Windows of each record estimated instead of the record whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Windows {
    /// Samples in a window.
    pub length: usize,
    /// Samples from one window's end to the next's.
    pub every: usize,
}

impl Windows {
    /// Why these windows cannot be cut at all (a window or a step of no
    /// samples), in the request's words; `None` when they can.
    ///
    /// ```
    /// use twostage::Windows;
    /// assert!(Windows { length: 100, every: 50 }.refused().is_none());
    /// let refused = Windows { length: 100, every: 0 }.refused().expect("a step of 0");
    /// assert!(refused.to_string().starts_with("a window of 100 samples every 0"));
    /// ```
    pub fn refused(self) -> Option<RequestProblem> {
        (self.length == 0 || self.every == 0).then_some(RequestProblem::EmptyWindow {
            length: self.length,
            every: self.every,
        })
    }

    /// The last sample (counted from 1) of each window of a record of
    /// `samples` samples, or why there is none: the record, named by
    /// `place`, shorter than one window. Windows that [`Self::refused`]
    /// refuses give no window.
    ///
    /// ```
    /// use twostage::Windows;
    /// let windows = Windows { length: 4, every: 3 };
    /// assert_eq!(windows.ends(10, "r.csv").ok(), Some(vec![4, 7, 10]));
    /// assert_eq!(
    ///     windows.ends(3, "r.csv").unwrap_err().to_string(),
    ///     "r.csv: 3 samples, shorter than the window of 4"
    /// );
    /// ```
    ///
    /// # Errors
    /// [`RecordFailure::ShorterThanWindow`].
    pub fn ends(self, samples: usize, place: &str) -> Result<Vec<usize>, RecordFailure> {
        if samples < self.length {
            return Err(RecordFailure::ShorterThanWindow {
                place: place.to_string(),
                samples,
                window: self.length,
            });
        }
        if self.refused().is_some() {
            return Ok(Vec::new());
        }
        Ok((self.length..=samples).step_by(self.every).collect())
    }
}

/// How a check ranks a record among the model's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CheckSettings {
    /// The most noisy runs of the model each record is ranked among.
    pub runs: usize,
    /// Score from this sample on, leaving out a transient.
    pub score_from: usize,
    /// Score up to this sample, not including it (`None`: to the end).
    pub score_to: Option<usize>,
}

impl Default for CheckSettings {
    fn default() -> Self {
        Self {
            runs: DEFAULT_CHECK_RUNS,
            score_from: 0,
            score_to: None,
        }
    }
}
