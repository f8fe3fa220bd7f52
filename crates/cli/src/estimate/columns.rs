//! What `--check` and `--refine` add to the table, the messages and the
//! plots.

use anyhow::{Context, Result};
use twostage::RecordCheck;
use twostage::fit::TerminationReason;
use twostage::models::IoData;

use crate::number::format_f64;

/// Why the refinement stopped, for the table: the descent's reason, or
/// `failed` (the TS estimate kept).
pub(super) fn refine_stop(refined: Option<&Result<Option<TerminationReason>, String>>) -> String {
    match refined {
        Some(Ok(Some(stop))) => stop.name().to_string(),
        Some(Err(_)) => "failed".into(),
        _ => String::new(),
    }
}

/// `DIR/ID.svg`: the record's outputs beside the model's noise-free
/// response at its estimate.
pub(super) fn plot_check(
    dir: &std::path::Path,
    id: &str,
    record: &IoData,
    check: &RecordCheck,
    outputs: &[String],
    sample_time: f64,
) -> Result<()> {
    let traces: Vec<twostage_plot::Trace<'_>> = outputs
        .iter()
        .enumerate()
        .map(|(j, name)| twostage_plot::Trace {
            name,
            measured: record.output(j),
            simulated: check.simulated.output(j),
        })
        .collect();
    let verdict = if check.explained() {
        "explained"
    } else {
        "not explained"
    };
    let title = format!("{id}: {verdict} by the model at its estimate");
    let svg = twostage_plot::record_vs_simulation(&title, sample_time, &traces)
        .with_context(|| format!("--plot: {id}"))?;
    std::fs::create_dir_all(dir).with_context(|| format!("--plot: creating {}", dir.display()))?;
    // An id is the user's text: keep the file name to safe characters.
    let name: String = id
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    twostage::write_whole(dir.join(format!("{name}.svg")), svg.as_bytes())?;
    Ok(())
}

/// Whether the record's input is the one every training record had, or,
/// where inputs vary from experiment to experiment, whether it lies in
/// the estimator's input family (`in_family`; `None` when there is none).
pub(super) fn input_as_trained(check: &RecordCheck, in_family: Option<bool>) -> Option<bool> {
    if check.input_shared {
        Some(check.input_differs_at.is_none())
    } else {
        in_family
    }
}

/// Numbers for a message, comma separated, to four significant digits
/// (a residual of 1.8e-6 must not read 0.0000).
pub(super) fn list(values: &[f64]) -> String {
    let shown: Vec<String> = values
        .iter()
        .map(|v| crate::number::four_digits(*v))
        .collect();
    shown.join(", ")
}

/// The check's columns: per output its RMS residual and fit, then the
/// tail probability, whether the record is explained, and the optima its
/// best-fit search ended in.
pub(super) fn check_header(outputs: &[String]) -> Vec<String> {
    let mut header = Vec::new();
    for y in outputs {
        header.push(format!("{y}_rms"));
        header.push(format!("{y}_fit_percent"));
    }
    header.extend([
        "check_tail_probability".into(),
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
pub(super) fn check_fields(
    outputs: usize,
    check: Option<&Result<RecordCheck, String>>,
    in_family: Option<bool>,
) -> Vec<String> {
    match check {
        Some(Ok(c)) => {
            let mut fields = Vec::new();
            for (rms, fit) in c.rms.iter().zip(&c.fit_percent) {
                fields.push(format_f64(*rms));
                fields.push(format_f64(*fit));
            }
            fields.push(format_f64(c.tail_probability));
            fields.push(c.reference_runs.to_string());
            fields.push(c.model_consistent().to_string());
            fields.push(format_f64(c.loss_ratio));
            fields.push(c.explained().to_string());
            fields.push(input_as_trained(c, in_family).map_or_else(String::new, |b| b.to_string()));
            fields.push(c.optima.to_string());
            fields.push(c.runner_up_ratio.map_or_else(String::new, format_f64));
            fields
        }
        _ => vec![String::new(); 2 * outputs + 8],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A message's numbers keep their significant digits, however small.
    #[test]
    fn a_small_residual_reads_as_itself() {
        assert_eq!(list(&[1.8e-6, 91.7]), "1.800e-6, 91.70");
    }
}
