//! What `estimate` says on stderr about each record: warnings about its
//! estimate, its refinement and its check, each failure shared by many
//! records said once, and each kind of out-of-distribution flag said in
//! one line naming every record it concerns.

use std::path::Path;

use twostage::JointOfRecords;
use twostage::RecordCheck;
use twostage::fit::TerminationReason;

use super::columns::list;
use twostage::sources::record_file::RecordFormat;
use twostage::{AutoRefined, RecordEstimate, RecordOutcome, RefineOutcome, Refined, RefinedBy};

/// The messages about one file's records.
pub(super) struct Said<'a> {
    file: String,
    format: &'a RecordFormat,
    /// The estimator's record length, where an estimator estimates.
    trained: Option<usize>,
    repeated: RepeatedFailures,
    outside: Outside,
}

/// The records flagged out of distribution, by what flagged them: said
/// at the end of the file, one line for each flag.
#[derive(Default)]
struct Outside {
    /// Experiment, Mahalanobis distance, threshold.
    features: Vec<(String, f64, f64)>,
    /// Experiment, the numbers outside the family.
    input: Vec<(String, String)>,
    /// Experiment, shape distance, threshold.
    shape: Vec<(String, f64, f64)>,
}

impl<'a> Said<'a> {
    pub(super) fn new(path: &Path, format: &'a RecordFormat, trained: Option<usize>) -> Self {
        Self {
            file: path.display().to_string(),
            format,
            trained,
            repeated: RepeatedFailures::default(),
            outside: Outside::default(),
        }
    }

    /// A record of another length than the estimator's: the estimate is
    /// still defined, but the validation error and the intervals were
    /// measured for another N (said only of a record that was estimated:
    /// a failed one says why).
    pub(super) fn note_length(&self, id: &str, outcome: &RecordOutcome) {
        if let (Ok((record, _)), Some(trained)) = (outcome, self.trained)
            && record.n_samples() != trained
        {
            eprintln!(
                "note: {}: experiment {id}: {} samples, the estimator was trained and \
                 validated on N = {trained}: its estimate only starts the refinement, \
                 which fits the record at its own length",
                self.file,
                record.n_samples()
            );
        }
    }

    /// Warnings about the estimate itself and its refinement.
    pub(super) fn warnings(&mut self, id: &str, estimated: &RecordEstimate) {
        if let Some((d, t)) = estimated.distance.filter(|(d, t)| d > t) {
            self.outside.features.push((id.to_string(), d, t));
        }
        if let Some(deviations) = estimated.input.as_ref().filter(|d| !d.is_empty()) {
            let said: Vec<String> = deviations.iter().map(ToString::to_string).collect();
            self.outside.input.push((id.to_string(), said.join("; ")));
        }
        if let Some((d, t)) = estimated
            .input_shape
            .filter(|_| estimated.input_shape_outside())
        {
            self.outside.shape.push((id.to_string(), d, t));
        }
        let file = &self.file;
        if let Some(floored) = estimated.floored.as_ref().filter(|f| !f.is_empty()) {
            let outputs = &self.format.outputs;
            let listed: Vec<String> = floored
                .iter()
                .take(5)
                .map(|f| {
                    let signal = outputs.get(f.output).map_or("?", String::as_str);
                    format!("{signal} = {} at sample {}", f.value, f.sample + 1)
                })
                .collect();
            eprintln!(
                "warning: {file}: experiment {id}: {} sample(s) outside the domain of the \
                 estimator's output transform ({}{}), taken at the smallest value \
                 the training records had; the estimate and its intervals do not \
                 speak for them",
                floored.len(),
                listed.join(", "),
                if floored.len() > 5 { ", ..." } else { "" }
            );
        }
        match &estimated.refinement {
            Some(RefineOutcome::Failed(e))
                if self.repeated.first("--refine", &e.to_string(), id) =>
            {
                eprintln!(
                    "warning: {file}: experiment {id}: --refine failed ({e}); the two-stage \
                 estimate is kept"
                )
            }
            Some(RefineOutcome::Done(Refined {
                by:
                    RefinedBy::Descent {
                        stop: TerminationReason::MaxIterations,
                        ..
                    },
                ..
            })) => eprintln!(
                "warning: {file}: experiment {id}: --refine did not converge within its \
                 iterations; the estimate is the best point it reached"
            ),
            _ => {}
        }
        if let Some(e) = estimated
            .refined()
            .and_then(|r| r.interval_failure.as_ref())
        {
            eprintln!(
                "warning: {file}: experiment {id}: the refined estimate has no interval \
                 ({e}); its _lo and _hi are NaN"
            );
        }
        if let (Some(_), Some(Ok(check))) = (estimated.refined(), &estimated.check)
            && !check.best_fit_consistent()
        {
            eprintln!(
                "note: {file}: experiment {id}: the model does not make this record \
                 exactly (not even its best fit misses it as the model's own records \
                 do: check_best_fit_tail_probability {}): the refined interval covers \
                 this record's noise about the model's best fit, not the error of the \
                 model itself, so the plant's true values may lie outside it",
                check.best_fit_tail_probability
            );
        }
    }

    /// What the check found, where it ran.
    pub(super) fn check(&mut self, id: &str, estimated: &RecordEstimate) {
        let file = &self.file;
        // Only an estimator learned one input; a check simulates on the
        // record's own.
        if let (
            Some(Ok(RecordCheck {
                input_differs_at: Some((j, k)),
                ..
            })),
            Some(_),
        ) = (&estimated.check, self.trained)
        {
            eprintln!(
                "warning: {file}: experiment {id}: its input {} differs from the one every \
                 training record had (from sample {}): the estimator learned that \
                 input and does not read this one, so its estimate is not for this \
                 record; train on this experiment's input, or on an input design",
                self.format.inputs.get(*j).map_or("?", String::as_str),
                k + 1
            );
        }
        match &estimated.check {
            Some(Err(e)) if self.repeated.first("--check", &e.to_string(), id) => eprintln!(
                "warning: {file}: experiment {id}: --check could not simulate the model at \
                 the estimate ({e}); the estimate is kept, unchecked"
            ),
            Some(Ok(c)) if !c.explained() && c.best_fit_consistent() => eprintln!(
                "warning: {file}: experiment {id}: not explained by the model at its \
                 estimate (fit {} %): the model's best fit (searched from the estimate \
                 and over the prior, fit {} %) makes the record to the model's own \
                 noise, and improves on the estimate as at most {:.1}% of the model's \
                 own records there would; do not trust this estimate (a record unlike \
                 the training records, a poor estimate or one in another basin: try \
                 --refine; docs/real-data.md)",
                list(&c.fit_percent),
                list(&c.best_fit_percent),
                100.0 * c.improvement_tail_probability
            ),
            Some(Ok(c)) if !c.explained() => eprintln!(
                "warning: {file}: experiment {id}: not explained by the model at its \
                 estimate: RMS residual {}, fit {} %, where the model's best fit \
                 (searched from the estimate and over the prior) fits {} %, and at \
                 most {:.1}% of its own records there miss by as much; do not trust \
                 this estimate (another input than training's, a poor estimate or one \
                 in another basin: try --refine; docs/real-data.md)",
                list(&c.rms),
                list(&c.fit_percent),
                list(&c.best_fit_percent),
                100.0 * c.tail_probability
            ),
            Some(Ok(c)) if !c.best_fit_consistent() => eprintln!(
                "note: {file}: experiment {id}: the estimate fits the record within 5% \
                 in RMS of the best fit the model reaches from the estimate and over \
                 its prior (fit {} %), but not even that best fit does to the model's \
                 own noise (at most {:.1}% of its records miss by as much): the model \
                 is not exact for this record; judge it by predicting a record it was \
                 not fitted to (docs/real-data.md)",
                list(&c.fit_percent),
                100.0 * c.best_fit_tail_probability
            ),
            _ => {}
        }
    }

    /// One line per failure many records shared, and per flag.
    pub(super) fn summarize(&self) {
        self.outside.summarize(&self.file);
        self.repeated.summarize(&self.file);
    }
}

impl Outside {
    /// One line for each flag that flagged any record: a record's own
    /// words for one, the records listed with their numbers for several.
    fn summarize(&self, file: &str) {
        let ids = |rows: &[String]| {
            let ids: Vec<&str> = rows.iter().map(String::as_str).collect();
            list_ids(&ids)
        };
        let features: Vec<String> = self.features.iter().map(|(id, _, _)| id.clone()).collect();
        match self.features.as_slice() {
            [] => {}
            [(id, d, t)] => eprintln!(
                "warning: {file}: experiment {id}: out of distribution: its features lie \
                 at Mahalanobis distance {d:.3} from the training features, beyond \
                 the {t:.3} that 99.9% of them stay within; the estimate extrapolates \
                 and the intervals do not cover it (is it the same model and input?)"
            ),
            [(_, _, t), ..] => eprintln!(
                "warning: {file}: experiments {}: out of distribution: their features lie \
                 at Mahalanobis distances {} from the training features, beyond the {t:.3} \
                 that 99.9% of them stay within; the estimates extrapolate and the \
                 intervals do not cover them (are they of the same model and input?)",
                ids(&features),
                numbers(self.features.iter().map(|(_, d, _)| *d)),
            ),
        }
        match self.input.as_slice() {
            [] => {}
            [(id, said)] => eprintln!(
                "warning: {file}: experiment {id}: out of distribution: its input lies outside \
                 the family the estimator was trained on ({said}); the estimate extrapolates \
                 and the intervals do not cover it (train on a design that covers this \
                 input: docs/your-own-model.md)"
            ),
            many => {
                let each: Vec<String> = many
                    .iter()
                    .take(SHOWN)
                    .map(|(id, said)| format!("experiment {id}: {said}"))
                    .collect();
                let ids_of: Vec<String> = many.iter().map(|(id, _)| id.clone()).collect();
                eprintln!(
                    "warning: {file}: experiments {}: out of distribution: their inputs lie \
                     outside the family the estimator was trained on ({}{}); the estimates \
                     extrapolate and the intervals do not cover them (train on a design that \
                     covers these inputs: docs/your-own-model.md)",
                    ids(&ids_of),
                    each.join("; "),
                    more(many.len()),
                );
            }
        }
        let shaped: Vec<String> = self.shape.iter().map(|(id, _, _)| id.clone()).collect();
        match self.shape.as_slice() {
            [] => {}
            [(id, d, t)] => eprintln!(
                "warning: {file}: experiment {id}: out of distribution: {}; the estimate \
                 extrapolates and the intervals do not cover it (train on a design that \
                 covers this input: docs/any-experiment.md)",
                twostage::models::input_shape_words(*d, *t)
            ),
            [(_, _, t), ..] => eprintln!(
                "warning: {file}: experiments {}: out of distribution: their input shapes \
                 (autocorrelations) lie at distances {} from the training records' nearest, \
                 beyond the {t:.3} that 99% of the held-out records' stay within; the \
                 estimates extrapolate and the intervals do not cover them (train on a \
                 design that covers these inputs: docs/any-experiment.md)",
                ids(&shaped),
                numbers(self.shape.iter().map(|(_, d, _)| *d)),
            ),
        }
    }
}

/// Records whose own numbers a grouped line shows.
const SHOWN: usize = 10;

/// The first [`SHOWN`] of `values`, and how many more.
fn numbers(values: impl ExactSizeIterator<Item = f64>) -> String {
    let n = values.len();
    let shown: Vec<String> = values.take(SHOWN).map(|v| format!("{v:.3}")).collect();
    format!("{}{}", shown.join(", "), more(n))
}

/// ", ..." (how many more) past the first [`SHOWN`] of `n`.
fn more(n: usize) -> String {
    if n > SHOWN {
        format!(" and {} more", n - SHOWN)
    } else {
        String::new()
    }
}

/// The records `--refine=auto` refines, for its note: "none", or their
/// ids grouped by reason.
pub(super) fn refine_reasons(auto: &AutoRefined, rows: &[(String, RecordOutcome)]) -> String {
    let groups = auto.groups(rows);
    if groups.is_empty() {
        return "none".into();
    }
    let parts: Vec<String> = groups
        .iter()
        .map(|(reason, ids)| format!("{} ({}): {}", ids.len(), reason.describe(), list_ids(ids)))
        .collect();
    format!("experiment(s) {}", parts.join("; "))
}

/// Experiment ids for a message: the first ten, and how many more.
pub(super) fn list_ids(ids: &[&str]) -> String {
    let shown = ids.iter().take(10).copied().collect::<Vec<_>>().join(", ");
    if ids.len() > 10 {
        format!("{shown} and {} more", ids.len() - 10)
    } else {
        shown
    }
}

/// Failures of --refine or --check seen before: the first of each kind
/// and message is said in full, the others only counted.
#[derive(Default)]
struct RepeatedFailures {
    /// (what failed, message) -> (the first experiment, the others).
    seen: std::collections::BTreeMap<(&'static str, String), (String, Vec<String>)>,
}

impl RepeatedFailures {
    /// Whether this failure is the first of its kind and message (to be
    /// said in full); a repeat is counted.
    fn first(&mut self, what: &'static str, message: &str, id: &str) -> bool {
        match self.seen.get_mut(&(what, message.to_string())) {
            Some((_, others)) => {
                others.push(id.to_string());
                false
            }
            None => {
                self.seen
                    .insert((what, message.to_string()), (id.to_string(), Vec::new()));
                true
            }
        }
    }

    /// One line per repeated failure: how many more records, which.
    fn summarize(&self, file: &str) {
        for ((what, _), (first, others)) in &self.seen {
            if others.is_empty() {
                continue;
            }
            let ids: Vec<&str> = others.iter().map(String::as_str).collect();
            eprintln!(
                "warning: {file}: {what} failed as for experiment {first} in {} more \
                 experiment(s): {}",
                others.len(),
                list_ids(&ids)
            );
        }
    }
}

/// What the joint fit of `plant`'s records (by name) did with each: the
/// records left out and why, those whose estimates disagree, and each
/// fitted record's fit at the joint estimate.
pub(super) fn joint(plant: &[&str], joint: &JointOfRecords) {
    let name = |i: usize| plant[i];
    for (i, why) in &joint.left_out {
        eprintln!(
            "warning: {}: left out of the joint fit: the model does not run on it: {why}",
            name(*i)
        );
    }
    if !joint.disagreeing.is_empty() {
        let names: Vec<&str> = joint.disagreeing.iter().map(|&i| name(i)).collect();
        eprintln!(
            "warning: the two-stage estimates of {} lie beyond their intervals from the \
             others': the records may not be of one plant (or one condition); they are \
             fitted with the rest, and the joint estimate is a compromise between them",
            names.join("; ")
        );
    }
    let fits: Vec<String> = joint
        .fitted
        .iter()
        .map(|(i, fit)| format!("{} {fit:.1}%", name(*i)))
        .collect();
    eprintln!(
        "note: joint estimate of {} of {} records ({} found{}); fit at it: {}",
        joint.fitted.len(),
        plant.len(),
        match joint.optima {
            1 => "1 optimum".to_string(),
            n => format!("{n} optima"),
        },
        joint.runner_up_ratio.map_or_else(String::new, |r| format!(
            ", the runner-up's loss {r:.3} times"
        )),
        fits.join(", ")
    );
}
