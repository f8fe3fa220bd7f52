//! What `--check` adds to the messages and the plots (the table's
//! columns are the library's: `Estimating::csv` and `Estimating::json`).

use anyhow::{Context, Result};
use twostage::RecordCheck;
use twostage::models::IoData;

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

/// Numbers for a message, comma separated, to four significant digits
/// (a residual of 1.8e-6 must not read 0.0000).
pub(super) fn list(values: &[f64]) -> String {
    let shown: Vec<String> = values
        .iter()
        .map(|v| crate::number::four_digits(*v))
        .collect();
    shown.join(", ")
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
