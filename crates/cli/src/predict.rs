//! `twostage simulate --at ESTIMATES.csv`: the model at given parameters,
//! one experiment per row of an estimate CSV, on a measured input where
//! the source can take one, to predict or to compare with a record.

use std::path::Path;

use anyhow::{Result, bail};
use rayon::prelude::*;
use twostage::models::{Conditions, IoData, Simulator, experiment_rng};
use twostage::sources::csv_rows::row;

use crate::number::format_f64;
use crate::usage;
use twostage::sources::record_file::{self, RecordFormat};

/// One row of an estimate CSV: the experiment's id and its parameters.
pub struct Row {
    /// The `experiment` column (or the row's number when there is none).
    pub id: String,
    /// The parameter vector, in the model's order.
    pub theta: Vec<f64>,
}

/// The rows of an estimate CSV ([`twostage::sources::parameter_values`]),
/// each row skipped for want of values said as a note.
///
/// # Errors
/// What the reader refuses (file, line, column).
pub fn read_rows(path: &Path, names: &[String]) -> Result<Vec<Row>> {
    let read = twostage::sources::parameter_values::read(path, names).map_err(usage)?;
    for skipped in &read.skipped {
        eprintln!("note: {skipped}");
    }
    Ok(read
        .rows
        .into_iter()
        .map(|(id, theta)| Row { id, theta })
        .collect())
}

/// The given inputs: none, one record for every row, or one per row
/// matched by experiment id.
pub enum Inputs {
    /// The simulator's own input design.
    Own,
    /// The same record for every row.
    One(IoData),
    /// Each row's own record, in the rows' order.
    PerRow(Vec<IoData>),
}

impl Inputs {
    /// The inputs of the record CSV at `path` for `rows`: a file of one
    /// record serves every row; a file of many must hold one whose
    /// experiment id is each row's.
    ///
    /// # Errors
    /// A file that cannot be read, a record that cannot be (file, row,
    /// column), or a row without its record.
    pub fn read(path: &Path, format: &RecordFormat, rows: &[Row]) -> Result<Self> {
        let mut records = record_file::read(path, format).map_err(|e| usage(e.to_string()))?;
        let checked = |r: record_file::ReadRecord| -> Result<(String, IoData)> {
            r.record
                .map(|record| (r.id.clone(), record))
                .map_err(|e| usage(format!("--input: {e}")))
        };
        if records.len() == 1 {
            let (_, record) = checked(records.remove(0))?;
            return Ok(Self::One(record));
        }
        let by_id: std::collections::HashMap<String, IoData> =
            records.into_iter().map(checked).collect::<Result<_>>()?;
        // Rows of one experiment (the draws of a posterior) share its record.
        let per_row = rows
            .iter()
            .map(|row| {
                by_id.get(&row.id).cloned().ok_or_else(|| {
                    usage(format!(
                        "--input {} holds no record of experiment {}: give one record for \
                         every row, or one per experiment of the estimates",
                        path.display(),
                        row.id
                    ))
                })
            })
            .collect::<Result<_>>()?;
        Ok(Self::PerRow(per_row))
    }

    /// Row `row`'s given record, if any.
    pub fn of(&self, row: usize) -> Option<&IoData> {
        match self {
            Self::Own => None,
            Self::One(record) => Some(record),
            Self::PerRow(records) => records.get(row),
        }
    }
}

/// Simulate `sim` at every row (experiment stream `i` of `seed` for row
/// `i`), in requests of the simulator's batch size (rows on inputs of
/// their own too: a block of them, each on its own), in parallel; the
/// records in the rows' order.
///
/// # Errors
/// The first row that fails, named by its experiment id.
pub fn simulate_rows(
    sim: &dyn Simulator,
    rows: &[Row],
    inputs: &Inputs,
    noiseless: bool,
    seed: u64,
    progress: &dyn twostage::Progress,
) -> Result<Vec<IoData>> {
    let batch = sim.batch_size().max(1);
    let starts: Vec<usize> = (0..rows.len()).step_by(batch).collect();
    let blocks: Vec<Vec<IoData>> = starts
        .par_iter()
        .map(|&start| -> Result<Vec<IoData>> {
            let block = &rows[start..(start + batch).min(rows.len())];
            let thetas: Vec<&[f64]> = block.iter().map(|r| r.theta.as_slice()).collect();
            let mut rngs: Vec<_> = (start..start + block.len())
                .map(|i| experiment_rng(seed, i as u64))
                .collect();
            let mut records = vec![IoData::default(); block.len()];
            let results = match inputs {
                Inputs::PerRow(given) => {
                    let noise = Conditions {
                        noiseless,
                        input: None,
                    };
                    let given = &given[start..start + block.len()];
                    sim.simulate_batch_on_inputs(&thetas, &mut rngs, given, noise, &mut records)
                }
                Inputs::Own | Inputs::One(_) => {
                    let conditions = Conditions {
                        noiseless,
                        input: inputs.of(start),
                    };
                    sim.simulate_batch_under(&thetas, &mut rngs, conditions, &mut records)
                }
            };
            progress.advance_step(block.len());
            for (row, result) in block.iter().zip(results) {
                if let Err(e) = result {
                    bail!("simulating experiment {} at {:?}: {e}", row.id, row.theta);
                }
            }
            Ok(records)
        })
        .collect::<Result<_>>()?;
    Ok(blocks.into_iter().flatten().collect())
}

/// The records as one CSV: `experiment`, then the model's signal names.
pub fn records_csv(sim: &dyn Simulator, rows: &[Row], records: &[IoData]) -> String {
    let spec = sim.spec();
    let mut text = row(std::iter::once("experiment")
        .chain(spec.input_names().iter().map(String::as_str))
        .chain(spec.output_names().iter().map(String::as_str)));
    for (r, record) in rows.iter().zip(records) {
        for k in 0..record.n_samples() {
            let values = (0..record.n_inputs())
                .map(|j| record.input(j)[k])
                .chain((0..record.n_outputs()).map(|j| record.output(j)[k]))
                .map(format_f64);
            text.push_str(&row(std::iter::once(r.id.clone()).chain(values)));
        }
    }
    text
}

/// One experiment's prediction band: its rows (the draws of its
/// posterior, simulated), and per output and sample the mean of their
/// outputs and the central band of `level` (a share, 0.9 say).
pub struct Band {
    /// The experiment.
    pub id: String,
    /// Its rows, in the file's order.
    pub rows: Vec<usize>,
    /// `[output][sample]`: mean, low and high.
    pub outputs: Vec<Vec<[f64; 3]>>,
}

/// The rows' simulated `records` gathered by experiment (in the order of
/// each experiment's first row), each experiment's band of `level`.
pub fn bands(rows: &[Row], records: &[IoData], level: f64) -> Vec<Band> {
    let mut order: Vec<(String, Vec<usize>)> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for (i, row) in rows.iter().enumerate() {
        let at = *index.entry(row.id.clone()).or_insert_with(|| {
            order.push((row.id.clone(), Vec::new()));
            order.len() - 1
        });
        order[at].1.push(i);
    }
    order
        .into_iter()
        .map(|(id, members)| {
            let first = &records[members[0]];
            let outputs = (0..first.n_outputs())
                .map(|j| {
                    (0..first.n_samples())
                        .map(|k| {
                            let mut values: Vec<f64> =
                                members.iter().map(|&m| records[m].output(j)[k]).collect();
                            let mean = values.iter().sum::<f64>() / values.len() as f64;
                            values.sort_by(f64::total_cmp);
                            let last = (values.len() - 1) as f64;
                            let tail = ((1.0 - level) / 2.0 * last).round() as usize;
                            [mean, values[tail], values[values.len() - 1 - tail]]
                        })
                        .collect()
                })
                .collect();
            Band {
                id,
                rows: members,
                outputs,
            }
        })
        .collect()
}

/// The bands as one CSV: `experiment`, the inputs of each experiment's
/// first row, then per output its mean, low and high
/// (`y_mean,y_low,y_high`).
pub fn bands_csv(sim: &dyn Simulator, bands: &[Band], records: &[IoData]) -> String {
    let spec = sim.spec();
    let band_columns = spec
        .output_names()
        .iter()
        .flat_map(|y| [format!("{y}_mean"), format!("{y}_low"), format!("{y}_high")]);
    let mut text = row(std::iter::once("experiment".to_string())
        .chain(spec.input_names().iter().cloned())
        .chain(band_columns));
    for band in bands {
        let first = &records[band.rows[0]];
        for k in 0..first.n_samples() {
            let values = (0..first.n_inputs())
                .map(|j| first.input(j)[k])
                .chain(band.outputs.iter().flat_map(|o| o[k]))
                .map(format_f64);
            text.push_str(&row(std::iter::once(band.id.clone()).chain(values)));
        }
    }
    text
}
