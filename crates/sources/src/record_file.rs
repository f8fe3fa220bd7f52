//! Reading a user's records from CSV (one file holds any number, of any
//! lengths; the chart files of `simulate` have their own streaming reader,
//! `ChartFiles`, bound to their truth.csv and fixed length): one record (`u,y`, the signal columns only) or
//! many (`experiment,u,y`, long format), with the columns named as the
//! estimator's signals (`u`, `y` for the built-in models; a model file's
//! names otherwise, or `u1,..,y1,..` as `simulate` writes them), in any
//! order, and optionally a `time` (or `t`) column, which must step by the
//! model's sample time. Every problem names the file, the row and the
//! column.

use std::collections::HashMap;
use std::path::Path;

use twostage_models::{IoData, SignalColumn};

use crate::csv_rows::{DataFileError, excerpt};

/// One record read from a file, or why it could not be.
pub struct ReadRecord {
    /// The experiment's id: the `experiment` column, or the file's stem.
    pub id: String,
    /// The record, or the problem with it (file, row, column).
    pub record: Result<IoData, DataFileError>,
}

/// How a model's records are laid out in a file: the names of its signals,
/// and the time between samples that a `time` column must step by.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordFormat {
    /// The inputs' column names.
    pub inputs: Vec<String>,
    /// The outputs' column names.
    pub outputs: Vec<String>,
    /// Seconds between samples.
    pub sample_time: f64,
}

impl RecordFormat {
    /// The records of the model `spec` describes.
    pub fn of(spec: &twostage_models::ModelSpec) -> Self {
        Self {
            inputs: spec.input_names().to_vec(),
            outputs: spec.output_names().to_vec(),
            sample_time: spec.sample_time(),
        }
    }
}

/// Read every record of one CSV file laid out as `format`: each record
/// whole, or why it could not be read (its file, row and column); the
/// records of an experiment in order of first appearance.
///
/// ```
/// use twostage_sources::record_file::{RecordFormat, read};
/// let dir = std::env::temp_dir().join("twostage-record-file-doc");
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("runs.csv");
/// std::fs::write(&path, "experiment,time,y,u\na,0,1.5,1\na,0.1,2,0\nb,0,x,1\n").unwrap();
/// let format = RecordFormat { inputs: vec!["u".into()], outputs: vec!["y".into()], sample_time: 0.1 };
/// let records = read(&path, &format)?;
/// assert_eq!(records[0].id, "a");
/// assert_eq!(records[0].record.as_ref().unwrap().output(0), &[1.5, 2.0]);
/// let problem = records[1].record.as_ref().unwrap_err();
/// assert_eq!((problem.row, problem.column.as_deref()), (Some(4), Some("y")));
/// assert!(problem.to_string().contains("runs.csv: row 4, column y: 'x' is not a finite number"));
/// # Ok::<(), twostage_sources::csv_rows::DataFileError>(())
/// ```
///
/// # Errors
/// A file that cannot be read or has no usable header: one line naming it.
pub fn read(path: &Path, format: &RecordFormat) -> Result<Vec<ReadRecord>, DataFileError> {
    let name = path.display().to_string();
    let text = read_text(path)?;
    let stem = path
        .file_stem()
        .map_or_else(|| name.clone(), |s| s.to_string_lossy().into_owned());
    parse(&text, &name, &stem, format)
}

/// A record file's text, held whole: refused before it is read where it
/// and its records would not fit in the memory this process may take, and
/// named by its line where it is not UTF-8 text.
fn read_text(path: &Path) -> Result<String, DataFileError> {
    let name = path.display().to_string();
    let size = std::fs::metadata(path)
        .map_err(|e| DataFileError::whole(&name, e.to_string()))?
        .len();
    // The text, and the records parsed from it (fewer bytes than text).
    if let Some(available) = twostage_models::available_memory()
        && size.saturating_mul(2) > available
    {
        return Err(DataFileError::whole(
            &name,
            format!(
                "a file of {} is read whole with its records, where this process has {} \
             available: split it into files of fewer experiments",
                twostage_models::readable_bytes(size as f64),
                twostage_models::readable_bytes(available as f64)
            ),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| DataFileError::whole(&name, e.to_string()))?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
        DataFileError::at(
            &name,
            line,
            "bytes that are not UTF-8 text: give a CSV file",
        )
    })
}

/// The SISO signals `u`, `y`, sampled every second.
#[cfg(test)]
fn siso() -> RecordFormat {
    RecordFormat {
        inputs: vec!["u".into()],
        outputs: vec!["y".into()],
        sample_time: 1.0,
    }
}

/// What a header lacks and has too many of, against the model's signals
/// (the order of the columns does not matter).
pub(crate) fn header_difference(fields: &[&str], signals: &[&str]) -> String {
    let missing: Vec<&str> = signals
        .iter()
        .filter(|s| !fields.contains(s))
        .copied()
        .collect();
    let extra: Vec<&str> = fields
        .iter()
        .filter(|f| !signals.contains(f))
        .copied()
        .collect();
    let twice: Vec<&str> = signals
        .iter()
        .filter(|s| fields.iter().filter(|f| f == s).count() > 1)
        .copied()
        .collect();
    let mut parts = Vec::new();
    if !missing.is_empty() {
        parts.push(format!("missing {}", missing.join(", ")));
    }
    if !extra.is_empty() {
        parts.push(format!(
            "extra {} (not a signal of the model: remove the column)",
            excerpt(&extra.join(", "))
        ));
    }
    if !twice.is_empty() {
        parts.push(format!("more than once {}", twice.join(", ")));
    }
    parts.push("the columns may come in any order".into());
    parts.join("; ")
}

/// One record as its rows arrive: a column of values per signal, the last
/// time seen, and the first problem.
struct Partial {
    columns: Vec<Vec<f64>>,
    last_time: Option<f64>,
    problem: Option<DataFileError>,
}

/// Parse the text of a CSV file called `name`; records without an
/// `experiment` column take `stem` as their id.
///
/// # Errors
/// As [`read`].
pub fn parse(
    text: &str,
    name: &str,
    stem: &str,
    format: &RecordFormat,
) -> Result<Vec<ReadRecord>, DataFileError> {
    let all: Vec<&str> = format
        .inputs
        .iter()
        .chain(&format.outputs)
        .map(String::as_str)
        .collect();
    let expected = format!(
        "{} or experiment,{} (with a time or t column if you like)",
        all.join(","),
        all.join(",")
    );
    // Every row, header first, as the shared CSV reader gives it.
    let mut rows: Vec<(usize, Vec<String>)> = Vec::new();
    crate::csv_rows::for_each_row(
        text.as_bytes(),
        |line, fields| {
            rows.push((line, fields.iter().map(str::to_string).collect()));
            Ok(())
        },
        |line, e| DataFileError {
            row: line,
            ..DataFileError::whole(name, e)
        },
    )?;
    let mut rows = rows.into_iter();
    let Some((_, fields)) = rows.next() else {
        return Err(DataFileError::whole(
            name,
            format!("the file is empty; expected a header {expected}"),
        ));
    };
    let header = fields.join(",");
    let fields: Vec<&str> = fields.iter().map(String::as_str).collect();
    let long = fields.first() == Some(&"experiment");
    let first = usize::from(long);
    // A time column is checked, not read into the record.
    let time = fields[first..]
        .iter()
        .position(|f| *f == "time" || *f == "t")
        .map(|c| first + c);
    let signal_at: Vec<usize> = (first..fields.len()).filter(|c| Some(*c) != time).collect();
    let signal_fields: Vec<&str> = signal_at.iter().map(|&c| fields[c]).collect();
    let placed = twostage_models::signal_columns(&signal_fields, &format.inputs, &format.outputs)
        .ok_or_else(|| {
        DataFileError::at(
            name,
            1,
            format!(
                "header '{}' is not {expected}: {}",
                excerpt(&header),
                header_difference(&signal_fields, &all)
            ),
        )
    })?;
    let width = fields.len();
    let (n_u, n_y) = (format.inputs.len(), format.outputs.len());
    // Records in the order their experiment first appears.
    let mut order: Vec<String> = Vec::new();
    let mut slots: HashMap<String, usize> = HashMap::new();
    let mut data: Vec<Partial> = Vec::new();
    for (row, values) in rows {
        let values: Vec<&str> = values.iter().map(String::as_str).collect();
        if values.len() != width {
            return Err(DataFileError::at(
                name,
                row,
                format!("{} values, the header has {width}", values.len()),
            ));
        }
        let id = if long { values[0] } else { stem };
        let slot = *slots.entry(id.to_string()).or_insert_with(|| {
            order.push(id.to_string());
            data.push(Partial {
                columns: vec![Vec::new(); n_u + n_y],
                last_time: None,
                problem: None,
            });
            order.len() - 1
        });
        let entry = &mut data[slot];
        if let Some(c) = time {
            let now = values[c].parse::<f64>().ok().filter(|v| v.is_finite());
            let problem = match (now, entry.last_time) {
                (None, _) => Some(format!("'{}' is not a finite time", values[c])),
                (Some(now), Some(before))
                    if ((now - before) - format.sample_time).abs()
                        > 1e-6 * format.sample_time.abs() =>
                {
                    Some(format!(
                        "time steps by {} from the row before; the model samples every {}",
                        now - before,
                        format.sample_time
                    ))
                }
                _ => None,
            };
            if let (Some(problem), None) = (problem, &entry.problem) {
                entry.problem = Some(DataFileError::at(name, row, problem).in_column(fields[c]));
            }
            entry.last_time = now;
        }
        for (placed, &c) in placed.iter().zip(&signal_at) {
            let text = values[c];
            let column = match *placed {
                SignalColumn::Input(j) => j,
                SignalColumn::Output(j) => n_u + j,
            };
            let value = text.parse::<f64>().ok().filter(|v| v.is_finite());
            if value.is_none() && entry.problem.is_none() {
                entry.problem = Some(
                    DataFileError::at(
                        name,
                        row,
                        format!("'{}' is not a finite number", excerpt(text)),
                    )
                    .in_column(fields[c]),
                );
            }
            // Keep the lengths aligned so later rows still parse.
            entry.columns[column].push(value.unwrap_or(0.0));
        }
    }
    Ok(order
        .into_iter()
        .zip(data)
        .map(
            |(
                id,
                Partial {
                    columns, problem, ..
                },
            )| ReadRecord {
                record: match problem {
                    Some(p) => Err(p),
                    None => {
                        let n = columns.first().map_or(0, Vec::len);
                        let mut record = IoData::zeros(n, n_u, n_y);
                        for (c, values) in columns.iter().enumerate() {
                            let target = if c < n_u {
                                record.input_mut(c)
                            } else {
                                record.output_mut(c - n_u)
                            };
                            target.copy_from_slice(values);
                        }
                        Ok(record)
                    }
                },
                id,
            },
        )
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn values(record: &ReadRecord) -> (Vec<u64>, Vec<u64>) {
        let data = record.record.as_ref().expect("a valid record");
        let bits = |s: &[f64]| s.iter().map(|v| v.to_bits()).collect();
        (bits(data.input(0)), bits(data.output(0)))
    }

    /// Experiments, each a list of (u, y) rows; ids are distinct.
    fn experiments() -> impl Strategy<Value = Vec<(String, Vec<(f64, f64)>)>> {
        let finite = prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO;
        let rows = prop::collection::vec((finite, finite), 1..20);
        prop::collection::btree_map("[a-z0-9_-]{1,6}", rows, 1..5)
            .prop_map(|m| m.into_iter().collect())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

        #[test]
        fn any_text_is_parsed_or_rejected_with_the_file_named(text in "\\PC*", header in 0usize..3) {
            let text = match header {
                0 => text,
                1 => format!("u,y\n{text}"),
                _ => format!("experiment,u,y\n{text}"),
            };
            match parse(&text, "data.csv", "data", &siso()) {
                Ok(records) => {
                    for r in records {
                        if let Err(problem) = r.record {
                            prop_assert_eq!(&problem.file, "data.csv", "{}", problem);
                        }
                    }
                }
                Err(problem) => prop_assert_eq!(&problem.file, "data.csv", "{}", problem),
            }
        }

        #[test]
        fn long_format_round_trips_bit_for_bit(experiments in experiments(), interleave in any::<bool>()) {
            let mut text = String::from("experiment, u, y\n");
            // Interleaved rows exercise grouping by id; order of first
            // appearance is still the order of `experiments`.
            let longest = experiments.iter().map(|(_, r)| r.len()).max().unwrap_or(0);
            if interleave {
                for k in 0..longest {
                    for (id, rows) in &experiments {
                        if let Some((u, y)) = rows.get(k) {
                            text.push_str(&format!("{id},{u},{y:e}\n\n"));
                        }
                    }
                }
            } else {
                for (id, rows) in &experiments {
                    for (u, y) in rows {
                        text.push_str(&format!(" {id} , {u:?} ,{y}\n"));
                    }
                }
            }
            let records = parse(&text, "f.csv", "f", &siso()).expect("valid text");
            prop_assert_eq!(records.len(), experiments.len());
            for (record, (id, rows)) in records.iter().zip(&experiments) {
                prop_assert_eq!(&record.id, id);
                let (u, y) = values(record);
                prop_assert_eq!(u, rows.iter().map(|r| r.0.to_bits()).collect::<Vec<_>>());
                prop_assert_eq!(y, rows.iter().map(|r| r.1.to_bits()).collect::<Vec<_>>());
            }
        }

        #[test]
        fn a_bad_value_names_its_row_and_column_and_spares_the_rest(
            experiments in experiments(),
            victim in any::<prop::sample::Index>(),
            row in any::<prop::sample::Index>(),
            column in 0usize..2,
            token in prop::sample::select(vec!["NaN", "inf", "-inf", "", "1e999", "x", "0x10"]),
        ) {
            let victim = victim.index(experiments.len());
            let bad_row = row.index(experiments[victim].1.len());
            let mut text = String::from("experiment,u,y\n");
            let mut file_row = 1;
            let mut expected_row = 0;
            for (e, (id, rows)) in experiments.iter().enumerate() {
                for (k, (u, y)) in rows.iter().enumerate() {
                    file_row += 1;
                    let (mut u, mut y) = (u.to_string(), y.to_string());
                    if e == victim && k == bad_row {
                        expected_row = file_row;
                        if column == 0 { u = token.to_string() } else { y = token.to_string() }
                    }
                    text.push_str(&format!("{id},{u},{y}\n"));
                }
            }
            let records = parse(&text, "f.csv", "f", &siso()).expect("valid header");
            for (e, record) in records.iter().enumerate() {
                if e == victim {
                    let problem = record.record.as_ref().expect_err("the bad record fails");
                    let name = ["u", "y"][column];
                    prop_assert_eq!(problem.row, Some(expected_row), "{}", problem);
                    prop_assert_eq!(problem.column.as_deref(), Some(name), "{}", problem);
                    let said = format!("f.csv: row {expected_row}, column {name}: '{token}'");
                    prop_assert!(problem.to_string().starts_with(&said), "{} vs {}", problem, said);
                } else {
                    prop_assert!(record.record.is_ok());
                }
            }
        }
    }

    #[test]
    fn headers_and_ragged_rows_are_rejected_with_their_row() {
        let problem = |text: &str| {
            parse(text, "f.csv", "f", &siso())
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert_eq!(
            problem("\n \n"),
            "f.csv: the file is empty; expected a header u,y or experiment,u,y (with a time or t \
             column if you like)"
        );
        assert!(problem("t,y\n1,2\n").starts_with("f.csv: row 1: header 't,y'"));
        assert_eq!(
            problem("u,y\n1,2\n\n3\n"),
            "f.csv: row 4: 1 values, the header has 2"
        );
        let records = parse("u,y\n1,2\n3,4\n", "f.csv", "f", &siso()).expect("valid");
        assert_eq!(records.len(), 1);
        assert_eq!(records[0].id, "f");
        assert_eq!(
            values(&records[0]),
            (
                vec![1f64.to_bits(), 3f64.to_bits()],
                vec![2f64.to_bits(), 4f64.to_bits()]
            )
        );
    }

    #[test]
    fn bytes_that_are_not_text_are_named_by_their_row() {
        let path = std::env::temp_dir().join(format!("not-text-{}.csv", std::process::id()));
        std::fs::write(&path, b"u,y\n1,2\n3,\xff\xfe\n").unwrap();
        let problem = read(&path, &siso()).err().unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(problem.row, Some(3), "{problem}");
        assert!(
            problem
                .to_string()
                .ends_with(": row 3: bytes that are not UTF-8 text: give a CSV file"),
            "{problem}"
        );
    }

    /// A sparse file of 100 GB: refused by its size, nothing read.
    #[test]
    #[cfg(target_os = "linux")]
    fn a_file_beyond_the_memory_is_refused_before_it_is_read() {
        let path = std::env::temp_dir().join(format!("huge-{}.csv", std::process::id()));
        let file = std::fs::File::create(&path).unwrap();
        file.set_len(100_000_000_000).unwrap();
        let problem = read(&path, &siso()).err().unwrap();
        std::fs::remove_file(&path).ok();
        if twostage_models::available_memory().is_some_and(|bytes| bytes < 50_000_000_000) {
            assert!(
                problem
                    .message
                    .starts_with("a file of 100.0 GB is read whole with its records, where"),
                "{problem}"
            );
        }
    }

    #[test]
    fn a_time_column_steps_by_the_sample_time() {
        let format = RecordFormat {
            sample_time: 0.02,
            ..siso()
        };
        let text = "time,u,y\n0,1,2\n0.02,3,4\n0.04,5,6\n";
        let records = parse(text, "f.csv", "f", &format).expect("valid");
        assert_eq!(
            values(&records[0]),
            (
                [1f64, 3.0, 5.0].map(f64::to_bits).to_vec(),
                [2f64, 4.0, 6.0].map(f64::to_bits).to_vec()
            )
        );
        // Each experiment's time is its own; `t` is a time column too.
        let text = "experiment,u,t,y\na,1,5,2\nb,1,0,2\na,3,5.02,4\nb,3,0.03,4\n";
        let records = parse(text, "f.csv", "f", &format).expect("valid header");
        assert!(records[0].record.is_ok());
        assert_eq!(
            records[1]
                .record
                .as_ref()
                .err()
                .map(ToString::to_string)
                .as_deref(),
            Some(
                "f.csv: row 5, column t: time steps by 0.03 from the row before; the model \
                 samples every 0.02"
            )
        );
        let records = parse("t,u,y\nnow,1,2\n", "f.csv", "f", &format).expect("valid header");
        assert_eq!(
            records[0]
                .record
                .as_ref()
                .err()
                .map(ToString::to_string)
                .as_deref(),
            Some("f.csv: row 2, column t: 'now' is not a finite time")
        );
    }

    /// Columns are found by the model's names, in any order, several
    /// inputs and outputs; the generic names work too.
    #[test]
    fn named_signals_in_any_order() {
        let signals = RecordFormat {
            inputs: vec!["force".into()],
            outputs: vec!["x".into(), "v".into()],
            sample_time: 1.0,
        };
        let text = "experiment,v,force,x\na,1,2,3\na,4,5,6\n";
        let records = parse(text, "f.csv", "f", &signals).expect("valid");
        let r = records[0].record.as_ref().expect("a record");
        assert_eq!(
            r.input(0).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            [2f64, 5.0].map(f64::to_bits)
        );
        assert_eq!(
            r.output(0).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            [3f64, 6.0].map(f64::to_bits)
        );
        assert_eq!(
            r.output(1).iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            [1f64, 4.0].map(f64::to_bits)
        );
        assert!(parse("u,y1,y2\n1,2,3\n", "f.csv", "f", &signals).is_ok());
        let e = parse("force,x\n1,2\n", "f.csv", "f", &signals)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert_eq!(
            e,
            "f.csv: row 1: header 'force,x' is not force,x,v or experiment,force,x,v (with a time \
             or t column if you like): missing v; the columns may come in any order"
        );
        let e = parse("force,x,x\n1,2,3\n", "f.csv", "f", &signals)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.ends_with("missing v; more than once x; the columns may come in any order"),
            "{e}"
        );
        // The right columns in another order, and one the model does not
        // have: the message names that one, not the order.
        let e = parse("t,v,pulse,force,x\n0,1,2,3,4\n", "f.csv", "f", &signals)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.ends_with(
                "extra pulse (not a signal of the model: remove the column); the columns may come \
                 in any order"
            ),
            "{e}"
        );
        assert!(parse("t,v,force,x\n0,1,2,3\n", "f.csv", "f", &signals).is_ok());
        // No input at all: outputs only.
        let autonomous = RecordFormat {
            inputs: vec![],
            outputs: vec!["I".into()],
            sample_time: 3.0,
        };
        let records = parse("I\n0.1\n0.2\n", "f.csv", "f", &autonomous).expect("valid");
        let r = records[0].record.as_ref().expect("a record");
        assert_eq!((r.n_inputs(), r.n_samples()), (0, 2));
    }
}
