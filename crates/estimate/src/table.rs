//! The table of an estimate request's rows, as the command line writes
//! it (CSV or JSON) and the Python package returns it (the JSON's
//! objects): one place for every column.

use twostage_models::input_shape_words;
use twostage_refine::RecordCheck;
use twostage_sources::csv_rows::{format_f64, row};

use super::refiner::RefinedBy;
use super::rows::{RecordEstimate, RefineOutcome, Refined};
use super::{Estimating, PosteriorDraws};

impl Estimating {
    /// The rows as the CSV table `twostage estimate` writes: a column
    /// per parameter, then those that some row has (window ends,
    /// intervals inside the prior's box, feature distances, the check's
    /// columns, why a refinement stopped, the search's optima and, with
    /// `with_correlation`, the refined estimates' correlations; with
    /// samples, each parameter's posterior draws' mean and sd), empty
    /// where a row has no value. Numbers read back to the same bits.
    pub fn csv(&self, rows: &[(String, RecordEstimate)], with_correlation: bool) -> String {
        let (names, outputs) = (&self.names, &self.signals.outputs);
        let prior_box = self.prior_box();
        let with_intervals = rows.iter().any(|(_, e)| e.half_widths.is_some());
        let with_distance = rows.iter().any(|(_, e)| e.distance.is_some());
        let mut header = vec!["experiment".to_string()];
        let windowed = rows.iter().any(|(_, e)| e.window_end.is_some());
        if windowed {
            header.push("window_end".into());
        }
        header.extend(names.iter().cloned());
        if with_intervals {
            for n in names {
                header.push(format!("{n}_lo"));
                header.push(format!("{n}_hi"));
            }
        }
        if with_distance {
            header.extend(["feature_distance".into(), "out_of_distribution".into()]);
        }
        let with_family = rows.iter().any(|(_, e)| e.input.is_some());
        if with_family {
            header.push("input_in_family".into());
        }
        let with_shape = rows.iter().any(|(_, e)| e.input_shape.is_some());
        if with_shape {
            header.push("input_shape_distance".into());
        }
        let with_floored = rows.iter().any(|(_, e)| e.floored.is_some());
        if with_floored {
            header.push("untransformed_samples".into());
        }
        let with_check = rows.iter().any(|(_, e)| e.check.is_some());
        if with_check {
            header.extend(check_header(outputs));
        }
        let with_stop = rows.iter().any(|(_, e)| !e.refine_stop().is_empty());
        if with_stop {
            header.push("refine_stop".into());
        }
        // The search's optima, where a refinement searched and no check
        // already wrote them.
        let with_optima = !with_check && rows.iter().any(|(_, e)| e.optima().is_some());
        if with_optima {
            header.extend(["optima".into(), "runner_up_over_best".into()]);
        }
        let with_posterior = rows.iter().any(|(_, e)| e.posterior.is_some());
        if with_posterior {
            header.extend(posterior_header(names));
        }
        let with_region = rows.iter().any(|(_, e)| region_level(e).is_some());
        if with_region {
            header.extend(REGION_COLUMNS.map(String::from));
        }
        let pairs = if with_correlation {
            self.correlation_pairs()
        } else {
            Vec::new()
        };
        header.extend(pairs.iter().map(|(name, _)| name.clone()));
        let mut text = row(&header);
        for (id, e) in rows {
            let mut fields = vec![id.clone()];
            if windowed {
                fields.push(e.window_end.map_or_else(String::new, |end| end.to_string()));
            }
            fields.extend(e.theta.iter().map(|t| format_f64(*t)));
            // A row without a column's value (the joint row has no feature
            // distance) leaves it empty, so that every row has every column.
            match e.interval(prior_box) {
                Some((lo, hi)) => {
                    for (lo, hi) in lo.iter().zip(&hi) {
                        fields.push(format_f64(*lo));
                        fields.push(format_f64(*hi));
                    }
                }
                None if with_intervals => fields.extend(vec![String::new(); 2 * names.len()]),
                None => {}
            }
            match e.distance {
                Some((d, _)) => {
                    fields.push(format_f64(d));
                    fields.push(e.out_of_distribution().to_string());
                }
                None if with_distance => fields.extend([String::new(), String::new()]),
                None => {}
            }
            if with_family {
                fields.push(
                    e.in_family()
                        .map_or_else(String::new, |inside| inside.to_string()),
                );
            }
            if with_shape {
                fields.push(
                    e.input_shape
                        .map_or_else(String::new, |(d, _)| format_f64(d)),
                );
            }
            if with_floored {
                fields.push(e.floored.as_ref().map_or(0, Vec::len).to_string());
            }
            if with_check {
                fields.extend(check_fields(outputs.len(), e));
            }
            if with_stop {
                fields.push(e.refine_stop().to_string());
            }
            if with_optima {
                let optima = e.optima();
                fields.push(optima.map_or_else(String::new, |o| o.count.to_string()));
                fields.push(
                    optima
                        .and_then(|o| o.runner_up_over_best)
                        .map_or_else(String::new, format_f64),
                );
            }
            if with_posterior {
                match &e.posterior {
                    Some(draws) => {
                        for (mean, sd) in draws.mean().iter().zip(draws.sd()) {
                            fields.push(format_f64(*mean));
                            fields.push(format_f64(sd));
                        }
                    }
                    None => fields.extend(vec![String::new(); 2 * names.len()]),
                }
            }
            if with_region {
                match region_level(e) {
                    Some(level) => {
                        fields.extend([format_f64(level), (level <= REGION_LEVEL).to_string()])
                    }
                    None => fields.extend([String::new(), String::new()]),
                }
            }
            for (_, at) in &pairs {
                fields.push(
                    e.correlation()
                        .map_or_else(String::new, |r| format_f64(r[*at])),
                );
            }
            text.push_str(&row(&fields));
        }
        text
    }

    /// The rows as the JSON table `twostage estimate --format json`
    /// writes and the Python package returns: an object per row, with
    /// the keys the CSV table's columns have where the row has a value.
    pub fn json(
        &self,
        rows: &[(String, RecordEstimate)],
        with_correlation: bool,
    ) -> serde_json::Value {
        let (names, outputs) = (&self.names, &self.signals.outputs);
        let prior_box = self.prior_box();
        let pairs = if with_correlation {
            self.correlation_pairs()
        } else {
            Vec::new()
        };
        let records: Vec<serde_json::Value> = rows
            .iter()
            .map(|(id, e)| {
                let mut object = serde_json::Map::new();
                object.insert("experiment".into(), id.clone().into());
                if let Some(end) = e.window_end {
                    object.insert("window_end".into(), end.into());
                }
                let bounds = e.interval(prior_box);
                for (j, n) in names.iter().enumerate() {
                    object.insert(n.clone(), e.theta[j].into());
                    if let Some((lo, hi)) = &bounds {
                        object.insert(format!("{n}_lo"), lo[j].into());
                        object.insert(format!("{n}_hi"), hi[j].into());
                    }
                }
                if let Some((d, _)) = e.distance {
                    object.insert("feature_distance".into(), d.into());
                    object.insert("out_of_distribution".into(), e.out_of_distribution().into());
                }
                if let Some(deviations) = &e.input {
                    object.insert("input_in_family".into(), e.in_family().into());
                    let mut said: Vec<serde_json::Value> =
                        deviations.iter().map(|d| d.to_string().into()).collect();
                    if let Some((d, t)) = e.input_shape.filter(|_| e.input_shape_outside()) {
                        said.push(input_shape_words(d, t).into());
                    }
                    if !said.is_empty() {
                        object.insert("input_outside_family".into(), said.into());
                    }
                }
                if let Some((d, _)) = e.input_shape {
                    object.insert("input_shape_distance".into(), d.into());
                }
                if let Some(floored) = &e.floored {
                    object.insert("untransformed_samples".into(), floored.len().into());
                }
                if !e.refine_stop().is_empty() {
                    object.insert("refine_stop".into(), e.refine_stop().into());
                }
                if let (Some(optima), None) = (e.optima(), &e.check) {
                    object.insert("optima".into(), optima.count.into());
                    if let Some(ratio) = optima.runner_up_over_best {
                        object.insert("runner_up_over_best".into(), ratio.into());
                    }
                }
                if let Some(draws) = &e.posterior {
                    let columns = posterior_header(names);
                    let values = draws.mean().into_iter().zip(draws.sd());
                    for (pair, (mean, sd)) in columns.chunks_exact(2).zip(values) {
                        object.insert(pair[0].clone(), mean.into());
                        object.insert(pair[1].clone(), sd.into());
                    }
                }
                if let Some(level) = region_level(e) {
                    object.insert(REGION_COLUMNS[0].into(), level.into());
                    object.insert(REGION_COLUMNS[1].into(), (level <= REGION_LEVEL).into());
                }
                if let Some(r) = e.correlation() {
                    for (name, at) in &pairs {
                        object.insert(name.clone(), r[*at].into());
                    }
                }
                match &e.check {
                    Some(Ok(c)) => {
                        for (j, y) in outputs.iter().enumerate() {
                            object.insert(format!("{y}_rms"), c.rms[j].into());
                            object.insert(format!("{y}_fit_percent"), c.fit_percent[j].into());
                        }
                        object.insert("check_tail_probability".into(), c.tail_probability.into());
                        object.insert(
                            "check_improvement_tail_probability".into(),
                            c.improvement_tail_probability.into(),
                        );
                        object.insert(
                            "check_best_fit_tail_probability".into(),
                            c.best_fit_tail_probability.into(),
                        );
                        object.insert("check_runs".into(), c.reference_runs.into());
                        object.insert("model_consistent".into(), c.model_consistent().into());
                        object.insert("loss_over_best".into(), c.loss_ratio.into());
                        object.insert("explained".into(), c.explained().into());
                        if let Some(same) = e.input_as_trained(c) {
                            object.insert("input_as_trained".into(), same.into());
                        }
                        object.insert("optima".into(), c.optima.into());
                        if let Some(ratio) = c.runner_up_ratio {
                            object.insert("runner_up_over_best".into(), ratio.into());
                        }
                    }
                    Some(Err(e)) => {
                        object.insert("check_error".into(), e.to_string().into());
                    }
                    None => {}
                }
                serde_json::Value::Object(object)
            })
            .collect();
        serde_json::Value::Array(records)
    }

    /// Every row's posterior draws as CSV: `experiment` (and `window_end`
    /// with windows), `draw` (from 0), `out_of_distribution` where the
    /// estimator flags records, then a column per parameter; rows
    /// without draws (the joint row) have none. Numbers read back to the
    /// same bits.
    ///
    pub fn draws_csv(&self, rows: &[(String, RecordEstimate)]) -> String {
        let windowed = rows.iter().any(|(_, e)| e.window_end.is_some());
        let mut header = vec!["experiment".to_string()];
        if windowed {
            header.push("window_end".into());
        }
        header.push("draw".into());
        // A record out of distribution has its draws flagged with it: they
        // are the network's extrapolation.
        let flagged = rows
            .iter()
            .any(|(_, e)| e.posterior.is_some() && e.distance.is_some());
        if flagged {
            header.push("out_of_distribution".into());
        }
        header.extend(self.names.iter().cloned());
        let mut text = row(&header);
        let q = self.names.len().max(1);
        for (id, e) in rows {
            let Some(draws) = &e.posterior else { continue };
            for (k, draw) in draws.draws().chunks_exact(q).enumerate() {
                let mut fields = vec![id.clone()];
                if windowed {
                    fields.push(e.window_end.map_or_else(String::new, |end| end.to_string()));
                }
                fields.push(k.to_string());
                if flagged {
                    fields.push(
                        e.distance
                            .map_or_else(String::new, |_| e.out_of_distribution().to_string()),
                    );
                }
                fields.extend(draw.iter().map(|v| format_f64(*v)));
                text.push_str(&row(&fields));
            }
        }
        text
    }

    /// The pairs of parameters a correlation column names, `corr_A_B` with A
    /// before B, with their place in the row-major matrix.
    pub fn correlation_pairs(&self) -> Vec<(String, usize)> {
        let names = &self.names;
        let q = names.len();
        (0..q)
            .flat_map(|a| (a + 1..q).map(move |b| (a, b)))
            .map(|(a, b)| (format!("corr_{}_{}", names[a], names[b]), a * q + b))
            .collect()
    }
}

impl RecordEstimate {
    /// Why the refinement stopped, for the table: the descent's reason, or
    /// `failed` (the TS estimate kept).
    pub fn refine_stop(&self) -> &'static str {
        match &self.refinement {
            Some(RefineOutcome::Done(Refined {
                by: RefinedBy::Descent { stop, .. },
                ..
            })) => stop.name(),
            Some(RefineOutcome::Failed(_)) => "failed",
            _ => "",
        }
    }

    /// Whether the record's input is the one every training record had, or,
    /// where inputs vary from experiment to experiment, whether it lies in
    /// the estimator's input family (`in_family`; `None` when there is none).
    pub fn input_as_trained(&self, check: &RecordCheck) -> Option<bool> {
        if check.input_shared {
            Some(check.input_differs_at.is_none())
        } else {
            self.in_family()
        }
    }
}

/// The level of the joint region a table says values lie inside or not.
const REGION_LEVEL: f64 = 0.9;

/// The columns of values tested against the posterior: the smallest level
/// of its region of highest density that holds them, and whether that is
/// within [`REGION_LEVEL`].
const REGION_COLUMNS: [&str; 2] = ["region_level", "in_region_90"];

fn region_level(e: &RecordEstimate) -> Option<f64> {
    e.posterior.as_ref().and_then(PosteriorDraws::region_level)
}

/// The posterior's columns: per parameter its draws' mean and sd.
fn posterior_header(names: &[String]) -> Vec<String> {
    names
        .iter()
        .flat_map(|n| [format!("{n}_posterior_mean"), format!("{n}_posterior_sd")])
        .collect()
}

/// The check's columns: per output its RMS residual and fit, then the
/// tail probabilities of its misfit, its best fit's improvement and its
/// best fit's misfit,
/// whether the record is explained, and the optima its best-fit search
/// ended in.
fn check_header(outputs: &[String]) -> Vec<String> {
    let mut header = Vec::new();
    for y in outputs {
        header.push(format!("{y}_rms"));
        header.push(format!("{y}_fit_percent"));
    }
    header.extend([
        "check_tail_probability".into(),
        "check_improvement_tail_probability".into(),
        "check_best_fit_tail_probability".into(),
        "check_runs".into(),
        "model_consistent".into(),
        "loss_over_best".into(),
        "explained".into(),
        "input_as_trained".into(),
        "optima".into(),
        "runner_up_over_best".into(),
    ]);
    header
}

/// The check's values for one record (empty where it could not be run).
fn check_fields(outputs: usize, e: &RecordEstimate) -> Vec<String> {
    match &e.check {
        Some(Ok(c)) => {
            let mut fields = Vec::new();
            for (rms, fit) in c.rms.iter().zip(&c.fit_percent) {
                fields.push(format_f64(*rms));
                fields.push(format_f64(*fit));
            }
            fields.push(format_f64(c.tail_probability));
            fields.push(format_f64(c.improvement_tail_probability));
            fields.push(format_f64(c.best_fit_tail_probability));
            fields.push(c.reference_runs.to_string());
            fields.push(c.model_consistent().to_string());
            fields.push(format_f64(c.loss_ratio));
            fields.push(c.explained().to_string());
            fields.push(
                e.input_as_trained(c)
                    .map_or_else(String::new, |b| b.to_string()),
            );
            fields.push(c.optima.to_string());
            fields.push(c.runner_up_ratio.map_or_else(String::new, format_f64));
            fields
        }
        _ => vec![String::new(); 2 * outputs + 10],
    }
}
