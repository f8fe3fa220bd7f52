//! What `estimate` says on stderr about each record: warnings about its
//! estimate, its refinement and its check, each failure shared by many
//! records said once, and each kind of out-of-distribution flag and of
//! note said in one line naming every record it concerns, over every
//! file of the run.

use crate::number::four_digits;
use std::path::Path;

use twostage::JointOfRecords;
use twostage::RecordCheck;
use twostage::fit::TerminationReason;

use super::columns::list;
use twostage::sources::record_file::RecordFormat;
use twostage::{AutoRefined, RecordEstimate, RecordOutcome, RefineOutcome, Refined, RefinedBy};

/// The messages about a run's records.
pub(super) struct Said<'a> {
    /// The file whose records are being said.
    file: String,
    format: &'a RecordFormat,
    /// The estimator's record length, where an estimator estimates.
    trained: Option<usize>,
    repeated: RepeatedFailures,
    outside: Outside,
    notes: Notes,
}

/// A record: the file it came from and its experiment id.
#[derive(Clone)]
struct Named {
    file: String,
    id: String,
}

/// The records flagged out of distribution, by what flagged them: said
/// at the end of the run, one line for each flag.
#[derive(Default)]
struct Outside {
    /// Record, Mahalanobis distance, threshold.
    features: Vec<(Named, f64, f64)>,
    /// Record, the numbers outside the family.
    input: Vec<(Named, String)>,
    /// Record, shape distance, threshold.
    shape: Vec<(Named, f64, f64)>,
}

/// Notes many records may share, said at the end of the run, one line
/// for each.
#[derive(Default)]
struct Notes {
    /// Records of another length than the estimator's, and theirs.
    lengths: Vec<(Named, usize)>,
    /// Refined records the model's best fit does not make to its noise,
    /// and the best fit's tail probability.
    not_exact: Vec<(Named, f64)>,
    /// Checked records whose estimate fits within 5% of a best fit that
    /// misses them: the fit in percent, the best fit's tail probability.
    near_an_inexact_best_fit: Vec<(Named, String, f64)>,
    /// What `--refine=auto` chose, where it ran.
    auto: Option<AutoChoices>,
}

/// `--refine=auto`'s choices over a run's files.
#[derive(Default)]
struct AutoChoices {
    files: Vec<String>,
    /// Records the check explained, of the records it checked.
    explained: usize,
    checked: usize,
    /// The records refined, by reason (described).
    by_reason: Vec<(String, Vec<Named>)>,
}

impl<'a> Said<'a> {
    pub(super) fn new(format: &'a RecordFormat, trained: Option<usize>) -> Self {
        Self {
            file: String::new(),
            format,
            trained,
            repeated: RepeatedFailures::default(),
            outside: Outside::default(),
            notes: Notes::default(),
        }
    }

    /// The records said next are `path`'s.
    pub(super) fn file(&mut self, path: &Path) {
        self.file = path.display().to_string();
    }

    fn named(&self, id: &str) -> Named {
        Named {
            file: self.file.clone(),
            id: id.to_string(),
        }
    }

    /// What `--refine=auto` chose in this file.
    pub(super) fn auto(&mut self, auto: &AutoRefined, rows: &[(String, RecordOutcome)]) {
        let groups: Vec<(String, Vec<Named>)> = auto
            .groups(rows)
            .into_iter()
            .map(|(reason, ids)| {
                let named = ids.iter().map(|id| self.named(id)).collect();
                (reason.describe().to_string(), named)
            })
            .collect();
        let file = self.file.clone();
        let choices = self.notes.auto.get_or_insert_with(AutoChoices::default);
        choices.files.push(file);
        choices.explained += auto.explained;
        choices.checked += auto.checked;
        for (reason, named) in groups {
            match choices.by_reason.iter_mut().find(|(r, _)| *r == reason) {
                Some((_, all)) => all.extend(named),
                None => choices.by_reason.push((reason, named)),
            }
        }
    }

    /// A record of another length than the estimator's: the estimate is
    /// still defined, but the validation error and the intervals were
    /// measured for another N (said only of a record that was estimated:
    /// a failed one says why).
    pub(super) fn note_length(&mut self, id: &str, outcome: &RecordOutcome) {
        if let (Ok((record, _)), Some(trained)) = (outcome, self.trained)
            && record.n_samples() != trained
        {
            let named = self.named(id);
            self.notes.lengths.push((named, record.n_samples()));
        }
    }

    /// Warnings about the estimate itself and its refinement.
    pub(super) fn warnings(&mut self, id: &str, estimated: &RecordEstimate) {
        if let Some((d, t)) = estimated.distance.filter(|(d, t)| d > t) {
            self.outside.features.push((self.named(id), d, t));
        }
        if let Some(deviations) = estimated.input.as_ref().filter(|d| !d.is_empty()) {
            let said: Vec<String> = deviations.iter().map(ToString::to_string).collect();
            self.outside.input.push((self.named(id), said.join("; ")));
        }
        if let Some((d, t)) = estimated
            .input_shape
            .filter(|_| estimated.input_shape_outside())
        {
            self.outside.shape.push((self.named(id), d, t));
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
                if self
                    .repeated
                    .first("--refine", &e.to_string(), self.named(id)) =>
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
            let named = self.named(id);
            self.notes
                .not_exact
                .push((named, check.best_fit_tail_probability));
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
            Some(Err(e))
                if self
                    .repeated
                    .first("--check", &e.to_string(), self.named(id)) =>
            {
                eprintln!(
                    "warning: {file}: experiment {id}: --check could not simulate the model at \
                 the estimate ({e}); the estimate is kept, unchecked"
                )
            }
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
            Some(Ok(c)) if !c.best_fit_consistent() => {
                let named = self.named(id);
                self.notes.near_an_inexact_best_fit.push((
                    named,
                    list(&c.fit_percent),
                    c.best_fit_tail_probability,
                ));
            }
            _ => {}
        }
    }

    /// One line per failure many records shared, per flag and per note.
    pub(super) fn summarize(&self) {
        self.notes.summarize(self.trained);
        self.outside.summarize();
        self.repeated.summarize();
    }
}

/// Records for a message: `file: experiment id` for one, `file:
/// experiments a, b` for several of one file, `experiments a (file), b
/// (other file)` across files; the first ten, and how many more.
fn who(records: &[&Named]) -> String {
    match records {
        [] => String::new(),
        [one] => format!("{}: experiment {}", one.file, one.id),
        [first, ..] if records.iter().all(|r| r.file == first.file) => {
            format!("{}: experiments {}", first.file, ids(records, false))
        }
        _ => format!("experiments {}", ids(records, true)),
    }
}

/// The records' ids, each with its file in brackets where `with_files`.
fn ids(records: &[&Named], with_files: bool) -> String {
    let each: Vec<String> = records
        .iter()
        .map(|r| {
            if with_files {
                format!("{} ({})", r.id, r.file)
            } else {
                r.id.clone()
            }
        })
        .collect();
    list_ids(&each.iter().map(String::as_str).collect::<Vec<_>>())
}

/// [`who`] of the records of `rows`, each row's first field.
fn who_of<T>(rows: &[(Named, T)]) -> String {
    who(&rows.iter().map(|(named, _)| named).collect::<Vec<_>>())
}

impl Notes {
    fn summarize(&self, trained: Option<usize>) {
        if let Some(AutoChoices {
            files,
            explained,
            checked,
            by_reason,
        }) = &self.auto
        {
            // One file: its name before the note, its records by id alone.
            let (whose, across) = match files.as_slice() {
                [file] => (format!("{file}: "), String::new()),
                _ => (String::new(), format!(" in {} files", files.len())),
            };
            let parts: Vec<String> = by_reason
                .iter()
                .map(|(reason, named)| {
                    let named: Vec<&Named> = named.iter().collect();
                    format!(
                        "{} ({reason}): {}",
                        named.len(),
                        ids(&named, files.len() > 1)
                    )
                })
                .collect();
            let refining = if parts.is_empty() {
                "none".to_string()
            } else {
                format!("experiment(s) {}", parts.join("; "))
            };
            eprintln!(
                "note: {whose}--refine=auto: the check explains {explained} of {checked} \
                 two-stage estimates{across}; refining {refining}"
            );
        }
        match (self.lengths.as_slice(), trained) {
            ([], _) | (_, None) => {}
            ([(_, n)], Some(trained)) => eprintln!(
                "note: {}: {n} samples, the estimator was trained and validated on N = \
                 {trained}: its estimate only starts the refinement, which fits the record \
                 at its own length",
                who_of(&self.lengths)
            ),
            (many, Some(trained)) => eprintln!(
                "note: {}: {} samples, the estimator was trained and validated on N = \
                 {trained}: their estimates only start the refinement, which fits each \
                 record at its own length",
                who_of(many),
                list_counts(many.iter().map(|(_, n)| *n))
            ),
        }
        match self.not_exact.as_slice() {
            [] => {}
            [(_, p)] => eprintln!(
                "note: {}: the model does not make this record exactly (not even its best \
                 fit misses it as the model's own records do: \
                 check_best_fit_tail_probability {p}): the refined estimate is the \
                 model's best fit itself, and its interval covers this record's noise \
                 about it, not the error of the model itself, so the plant's true values \
                 may lie outside it",
                who_of(&self.not_exact)
            ),
            many => eprintln!(
                "note: {}: the model does not make these records exactly (not even their \
                 best fits miss them as the model's own records do: \
                 check_best_fit_tail_probability {}): the refined estimates are the \
                 model's best fits themselves, and their intervals cover each record's \
                 noise about them, not the error of the model itself, so the plant's true \
                 values may lie outside them",
                who_of(many),
                numbers(many.iter().map(|(_, p)| *p))
            ),
        }
        match self.near_an_inexact_best_fit.as_slice() {
            [] => {}
            [(named, fit, p)] => eprintln!(
                "note: {}: the estimate fits the record within 5% in RMS of the best fit \
                 the model reaches from the estimate and over its prior (fit {fit} %), but \
                 not even that best fit does to the model's own noise (at most {:.1}% of \
                 its records miss by as much): the model is not exact for this record; \
                 judge it by predicting a record it was not fitted to (docs/real-data.md)",
                who(&[named]),
                100.0 * p
            ),
            many => {
                let fits: Vec<&str> = many.iter().map(|(_, fit, _)| fit.as_str()).collect();
                let worst = many.iter().fold(0.0f64, |m, (_, _, p)| m.max(*p));
                eprintln!(
                    "note: {}: the estimates fit the records within 5% in RMS of the best \
                     fits the model reaches from them and over its prior (fit {} %), but \
                     not even those best fits do to the model's own noise (at most {:.1}% \
                     of its records miss by as much): the model is not exact for these \
                     records; judge it by predicting a record it was not fitted to \
                     (docs/real-data.md)",
                    who(&many.iter().map(|(named, _, _)| named).collect::<Vec<_>>()),
                    list_ids(&fits),
                    100.0 * worst
                );
            }
        }
    }
}

/// Whole numbers for a message: the first ten, and how many more.
fn list_counts(counts: impl Iterator<Item = usize>) -> String {
    let counts: Vec<String> = counts.map(|n| n.to_string()).collect();
    list_ids(&counts.iter().map(String::as_str).collect::<Vec<_>>())
}

impl Outside {
    /// One line for each flag that flagged any record: a record's own
    /// words for one, the records listed with their numbers for several.
    fn summarize(&self) {
        match self.features.as_slice() {
            [] => {}
            [(named, d, t)] => eprintln!(
                "warning: {}: out of distribution: its features lie at Mahalanobis distance \
                 {d:.3} from the training features, beyond the {t:.3} that 99.9% of them \
                 stay within; the estimate extrapolates and the intervals do not cover it \
                 (is it the same model and input?)",
                who(&[named])
            ),
            [(_, _, t), ..] => eprintln!(
                "warning: {}: out of distribution: their features lie at Mahalanobis \
                 distances {} from the training features, beyond the {t:.3} that 99.9% of \
                 them stay within; the estimates extrapolate and the intervals do not cover \
                 them (are they of the same model and input?)",
                who(&self.features.iter().map(|(n, _, _)| n).collect::<Vec<_>>()),
                numbers(self.features.iter().map(|(_, d, _)| *d)),
            ),
        }
        match self.input.as_slice() {
            [] => {}
            [(named, said)] => eprintln!(
                "warning: {}: out of distribution: its input lies outside the family the \
                 estimator was trained on ({said}); the estimate extrapolates and the \
                 intervals do not cover it (train on a design that covers this input: \
                 docs/your-own-model.md)",
                who(&[named])
            ),
            many => {
                let each: Vec<String> = many
                    .iter()
                    .take(SHOWN)
                    .map(|(named, said)| format!("experiment {}: {said}", named.id))
                    .collect();
                eprintln!(
                    "warning: {}: out of distribution: their inputs lie outside the family \
                     the estimator was trained on ({}{}); the estimates extrapolate and the \
                     intervals do not cover them (train on a design that covers these \
                     inputs: docs/your-own-model.md)",
                    who_of(many),
                    each.join("; "),
                    more(many.len()),
                );
            }
        }
        match self.shape.as_slice() {
            [] => {}
            [(named, d, t)] => eprintln!(
                "warning: {}: out of distribution: {}; the estimate extrapolates and the \
                 intervals do not cover it (train on a design that covers this input: \
                 docs/any-experiment.md)",
                who(&[named]),
                twostage::models::input_shape_words(*d, *t)
            ),
            [(_, _, t), ..] => eprintln!(
                "warning: {}: out of distribution: their input shapes (autocorrelations) lie \
                 at distances {} from the training records' nearest, beyond the {t:.3} that \
                 99% of the held-out records' stay within; the estimates extrapolate and the \
                 intervals do not cover them (train on a design that covers these inputs: \
                 docs/any-experiment.md)",
                who(&self.shape.iter().map(|(n, _, _)| n).collect::<Vec<_>>()),
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
    let printed: Vec<String> = values.map(|v| format!("{v:.3}")).collect();
    // Many records at one value (a floor, a threshold): said once.
    if n > 1 && printed.iter().all(|p| *p == printed[0]) {
        return format!("{} each", printed[0]);
    }
    let shown: Vec<&str> = printed.iter().take(SHOWN).map(String::as_str).collect();
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
    /// (what failed, message) -> (the first record, the others).
    seen: std::collections::BTreeMap<(&'static str, String), (Named, Vec<Named>)>,
}

impl RepeatedFailures {
    /// Whether this failure is the first of its kind and message (to be
    /// said in full); a repeat is counted.
    fn first(&mut self, what: &'static str, message: &str, record: Named) -> bool {
        match self.seen.get_mut(&(what, message.to_string())) {
            Some((_, others)) => {
                others.push(record);
                false
            }
            None => {
                self.seen
                    .insert((what, message.to_string()), (record, Vec::new()));
                true
            }
        }
    }

    /// One line per repeated failure: how many more records, which.
    fn summarize(&self) {
        for ((what, _), (first, others)) in &self.seen {
            if others.is_empty() {
                continue;
            }
            let all_one_file = others.iter().all(|r| r.file == first.file);
            let others: Vec<&Named> = others.iter().collect();
            let (whose, first_id) = if all_one_file {
                (format!("{}: ", first.file), first.id.clone())
            } else {
                (String::new(), format!("{} ({})", first.id, first.file))
            };
            eprintln!(
                "warning: {whose}{what} failed as for experiment {first_id} in {} more \
                 experiment(s): {}",
                others.len(),
                ids(&others, !all_one_file)
            );
        }
    }
}

/// What the joint fit of `plant`'s records (by name) did with each: the
/// records left out and why, those whose estimates disagree, the
/// parameters (named `params`) whose width the scatter between the
/// records sets, and each fitted record's fit at the joint estimate.
pub(super) fn joint(plant: &[&str], params: &[String], joint: &JointOfRecords) {
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
             others': the records may not be of one plant (or one condition), or the model \
             may miss part of the plant, so that its best fit moves with each record's \
             input; they are fitted with the rest, and the joint estimate is a compromise \
             between them",
            names.join("; ")
        );
    }
    if let Some(between) = &joint.between {
        let wide: Vec<String> = between
            .mismatch_sets_width()
            .iter()
            .enumerate()
            .filter(|(_, wide)| **wide)
            .map(|(j, _)| {
                format!(
                    "{} {} against {}",
                    params[j],
                    four_digits(between.sd[j]),
                    four_digits(between.within_sd[j])
                )
            })
            .collect();
        if !wide.is_empty() {
            eprintln!(
                "note: the records' own best fits scatter beyond their noise (sd between records \
                 against a record's own: {}): the model's mismatch with the plant, not the \
                 noise, sets these widths; the joint interval and each record's include the \
                 scatter",
                wide.join(", ")
            );
        }
    }
    let own = joint.has_own_parameters();
    let fits: Vec<String> = joint
        .fitted
        .iter()
        .map(|(i, fit)| {
            if own {
                format!("{} (row joint[{i}]) {fit:.1}%", name(*i))
            } else {
                format!("{} {fit:.1}%", name(*i))
            }
        })
        .collect();
    if own {
        let names: Vec<&str> = params
            .iter()
            .zip(&joint.per_record)
            .filter(|(_, own)| **own)
            .map(|(p, _)| p.as_str())
            .collect();
        eprintln!(
            "note: {} {} to each record (per_record in the model file): each record gets its \
             own value in its row joint[K], beside the plant's parameters the records share",
            names.join(", "),
            if names.len() == 1 {
                "belongs"
            } else {
                "belong"
            }
        );
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn named(file: &str, id: &str) -> Named {
        Named {
            file: file.into(),
            id: id.into(),
        }
    }

    #[test]
    fn records_are_named_with_their_files_only_across_files() {
        let (a, b, c) = (
            named("x.csv", "0"),
            named("x.csv", "1"),
            named("y.csv", "b"),
        );
        assert_eq!(who(&[&a]), "x.csv: experiment 0");
        assert_eq!(who(&[&a, &b]), "x.csv: experiments 0, 1");
        assert_eq!(who(&[&a, &c]), "experiments 0 (x.csv), b (y.csv)");
        let many: Vec<Named> = (0..12).map(|i| named(&format!("{i}.csv"), "r")).collect();
        let many: Vec<&Named> = many.iter().collect();
        assert!(
            who(&many).ends_with("r (9.csv) and 2 more"),
            "{}",
            who(&many)
        );
    }

    #[test]
    fn one_value_many_records_share_is_said_once() {
        assert_eq!(numbers([0.005, 0.005, 0.005].into_iter()), "0.005 each");
        assert_eq!(numbers([0.005, 0.25].into_iter()), "0.005, 0.250");
        assert_eq!(numbers([0.5].into_iter()), "0.500");
        let twelve = numbers((0..12).map(f64::from));
        assert!(twelve.ends_with("9.000 and 2 more"), "{twelve}");
    }
}
