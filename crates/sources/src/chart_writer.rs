//! A chart written as the CSV layout [`ChartFiles`](crate::ChartFiles)
//! reads: DIR/truth.csv (`experiment,<parameters>`) and DIR/data.csv
//! (`experiment,<inputs>,<outputs>`, one row per sample), the experiments
//! drawn from the model's prior and simulated in parallel blocks, written
//! in order.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use twostage_models::{IoData, Simulator, run_experiments};

use crate::csv_rows::{format_f64, row};
use crate::error::{Error, Result};

/// Experiments are simulated in parallel in blocks and written in order, so
/// that memory stays bounded and the files do not depend on the thread count.
const BLOCK: usize = 256;

/// The two files of a chart written by [`write_csv_chart`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvChart {
    /// DIR/data.csv, the records.
    pub data: PathBuf,
    /// DIR/truth.csv, their parameters.
    pub truth: PathBuf,
}

/// Simulates `count` experiments of `sim`, drawn from its prior with
/// `seed` (experiment i on its own stream, so the files do not depend on
/// the thread count), and writes them to `dir` as a CSV chart.
///
/// ```
/// use twostage_models::{Benchmark, Simulator};
/// use twostage_sources::{ChartFiles, write_csv_chart};
/// let dir = std::env::temp_dir().join("twostage-doc-csv-chart");
/// let written = write_csv_chart(&Benchmark::new(), 3, 7, &dir)?;
/// let chart = ChartFiles::open(&dir, Benchmark::new().spec())?;
/// assert_eq!((chart.len(), written.truth, written.data), (3, dir.join("truth.csv"), dir.join("data.csv")));
/// # std::fs::remove_dir_all(&dir).ok();
/// # Ok::<(), twostage_sources::Error>(())
/// ```
///
/// # Errors
/// No experiment asked, the folder or a file that cannot be written, or
/// an experiment whose simulation fails (its index named).
pub fn write_csv_chart(
    sim: &dyn Simulator,
    count: usize,
    seed: u64,
    dir: &Path,
) -> Result<CsvChart> {
    if count == 0 {
        return Err(Error::InvalidSetting(crate::error::InvalidSetting {
            name: "count",
            value: "0".into(),
            reason: "at least 1 experiment".into(),
        }));
    }
    let spec = sim.spec();
    let design = spec.prior().design(count, seed)?;
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |cause| Error::Io { path, cause }
    };
    fs::create_dir_all(dir).map_err(io(dir))?;
    let chart = CsvChart {
        data: dir.join("data.csv"),
        truth: dir.join("truth.csv"),
    };
    let open = |path: &Path| File::create(path).map(BufWriter::new).map_err(io(path));
    let (mut data, mut truth) = (open(&chart.data)?, open(&chart.truth)?);
    let signals = spec
        .input_names()
        .iter()
        .chain(spec.output_names())
        .cloned();
    write!(
        data,
        "{}",
        row(std::iter::once("experiment".to_string()).chain(signals))
    )
    .map_err(io(&chart.data))?;
    write!(
        truth,
        "{}",
        row(std::iter::once("experiment").chain(spec.param_names().iter().map(String::as_str)))
    )
    .map_err(io(&chart.truth))?;
    // A command source answers a request of its batch at once.
    let batch = sim.batch_size().clamp(1, BLOCK);
    let q = spec.n_params();
    for start in (0..count).step_by(BLOCK) {
        let end = (start + BLOCK).min(count);
        let block: Vec<Vec<(String, String)>> = (start..end)
            .step_by(batch)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|first| -> Result<Vec<(String, String)>> {
                let n = batch.min(end - first);
                let (mut thetas, mut records) = (vec![0.0; n * q], vec![IoData::default(); n]);
                let results = run_experiments(sim, &design, first, &mut thetas, &mut records);
                results
                    .into_iter()
                    .zip(&records)
                    .zip(thetas.chunks_exact(q.max(1)))
                    .enumerate()
                    .map(|(k, ((result, record), theta))| {
                        let index = first + k;
                        result.map_err(|error| Error::Experiment { index, error })?;
                        let mut rows = String::with_capacity(record.n_samples() * 56);
                        push_record_rows(&mut rows, Some(index), record);
                        let values: Vec<String> = theta.iter().map(|v| format_f64(*v)).collect();
                        Ok((rows, format!("{index},{}\n", values.join(","))))
                    })
                    .collect()
            })
            .collect::<Result<_>>()?;
        for (rows, truth_row) in block.into_iter().flatten() {
            data.write_all(rows.as_bytes()).map_err(io(&chart.data))?;
            truth
                .write_all(truth_row.as_bytes())
                .map_err(io(&chart.truth))?;
        }
    }
    data.flush().map_err(io(&chart.data))?;
    truth.flush().map_err(io(&chart.truth))?;
    Ok(chart)
}

/// A record's samples as CSV rows (inputs then outputs, each number as
/// [`format_f64`] writes it), each after `experiment,` when given: the
/// rows of a chart's data.csv, or of one record's CSV.
///
/// ```
/// use twostage_models::IoData;
/// use twostage_sources::chart_writer::push_record_rows;
/// let mut text = String::new();
/// push_record_rows(&mut text, Some(4), &IoData::siso(&[1.0, 0.5], &[-2.0, 0.25])?);
/// assert_eq!(text, "4,1,-2\n4,0.5,0.25\n");
/// # Ok::<(), twostage_models::SimError>(())
/// ```
pub fn push_record_rows(text: &mut String, experiment: Option<usize>, record: &IoData) {
    let signals: Vec<&[f64]> = (0..record.n_inputs())
        .map(|j| record.input(j))
        .chain((0..record.n_outputs()).map(|j| record.output(j)))
        .collect();
    for k in 0..record.n_samples() {
        if let Some(i) = experiment {
            text.push_str(&i.to_string());
            text.push(',');
        }
        for (j, signal) in signals.iter().enumerate() {
            if j > 0 {
                text.push(',');
            }
            text.push_str(&format_f64(signal[k]));
        }
        text.push('\n');
    }
}

#[cfg(test)]
mod tests {
    use twostage_models::{Conditions, ExperimentRng, ModelSpec, Prior, SimError};

    use super::*;

    /// Outputs its parameter, and fails above 0.5.
    struct FailsHigh(ModelSpec);

    impl Simulator for FailsHigh {
        fn spec(&self) -> &ModelSpec {
            &self.0
        }
        fn simulate_one(
            &self,
            theta: &[f64],
            _rng: &mut ExperimentRng,
            _: Conditions<'_>,
            out: &mut IoData,
        ) -> twostage_models::Result<()> {
            if theta[0] > 0.5 {
                return Err(SimError::Diverged {
                    theta: theta.to_vec(),
                    time: 0.0,
                });
            }
            *out = IoData::siso(&[1.0; 4], &[theta[0]; 4])?;
            Ok(())
        }
    }

    #[test]
    fn a_failing_experiment_is_named_and_the_rows_read_back() {
        let spec = |low, high| {
            ModelSpec::new(
                "f",
                &["a"],
                Prior::uniform_box(&[low], &[high]).unwrap(),
                1.0,
                4,
            )
            .unwrap()
        };
        let dir =
            std::env::temp_dir().join(format!("twostage-chart-writer-{}", std::process::id()));
        // Every draw below 0.5: written, and read back to the same values.
        let written = write_csv_chart(&FailsHigh(spec(0.0, 0.5)), 5, 3, &dir).unwrap();
        let chart = crate::ChartFiles::open(&dir, &spec(0.0, 0.5)).unwrap();
        let mut outputs = Vec::new();
        chart
            .for_each_record(&spec(0.0, 0.5), |row, record| {
                outputs.push((row, record.output(0)[0]));
                Ok(())
            })
            .unwrap();
        for (row, output) in outputs {
            assert_eq!(chart.theta(row), &[output]);
        }
        assert!(written.data.ends_with("data.csv"));
        // Every draw above: the first experiment is named.
        let failed = write_csv_chart(&FailsHigh(spec(0.6, 0.9)), 5, 3, &dir).unwrap_err();
        assert!(
            matches!(failed, Error::Experiment { index: 0, .. }),
            "{failed}"
        );
        assert!(
            failed.to_string().starts_with("simulating experiment 0: "),
            "{failed}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
