//! Reading records from CSV: `u,y` (one record) or `experiment,u,y` (many,
//! long format). Every problem names the file, the row and the column.

use std::collections::HashMap;
use std::path::Path;

use twostage::models::IoData;

/// One record read from a file, or why it could not be.
pub struct ReadRecord {
    /// The experiment's id: the `experiment` column, or the file's stem.
    pub id: String,
    /// The record, or the problem with it (file, row, column).
    pub record: Result<IoData, String>,
}

/// Read every record of one CSV file.
///
/// # Errors
/// A file that cannot be read or has no usable header: one line naming it.
pub fn read(path: &Path) -> Result<Vec<ReadRecord>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let name = path.display().to_string();
    let stem = path
        .file_stem()
        .map_or_else(|| name.clone(), |s| s.to_string_lossy().into_owned());
    parse(&text, &name, &stem)
}

/// Parse the text of a CSV file called `name`; records of the `u,y` form
/// take `stem` as their id.
///
/// # Errors
/// As [`read`].
pub fn parse(text: &str, name: &str, stem: &str) -> Result<Vec<ReadRecord>, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(format!(
            "{name}: the file is empty; expected a header u,y or experiment,u,y"
        ));
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let long = match columns.as_slice() {
        ["u", "y"] => false,
        ["experiment", "u", "y"] => true,
        _ => {
            return Err(format!(
                "{name}: row 1: header '{header}' is neither u,y nor experiment,u,y"
            ));
        }
    };
    // Records in the order their experiment first appears.
    let mut order: Vec<String> = Vec::new();
    let mut slots: HashMap<String, usize> = HashMap::new();
    let mut data: Vec<(Vec<f64>, Vec<f64>, Option<String>)> = Vec::new();
    for (index, line) in lines {
        let row = index + 1;
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != columns.len() {
            return Err(format!(
                "{name}: row {row}: {} values, the header has {}",
                fields.len(),
                columns.len()
            ));
        }
        let id = if long { fields[0] } else { stem };
        let slot = match slots.get(id) {
            Some(&slot) => slot,
            None => {
                slots.insert(id.to_string(), order.len());
                order.push(id.to_string());
                data.push((Vec::new(), Vec::new(), None));
                order.len() - 1
            }
        };
        let entry = &mut data[slot];
        let offset = usize::from(long);
        for (k, column) in ["u", "y"].iter().enumerate() {
            let text = fields[offset + k];
            let value = text.parse::<f64>().ok().filter(|v| v.is_finite());
            match value {
                Some(v) if k == 0 => entry.0.push(v),
                Some(v) => entry.1.push(v),
                None => {
                    if entry.2.is_none() {
                        entry.2 = Some(format!(
                            "{name}: row {row}, column {column}: '{text}' is not a finite number"
                        ));
                    }
                    // Keep the lengths aligned so later rows still parse.
                    if k == 0 {
                        entry.0.push(0.0);
                    } else {
                        entry.1.push(0.0);
                    }
                }
            }
        }
    }
    Ok(order
        .into_iter()
        .zip(data)
        .map(|(id, (u, y, problem))| ReadRecord {
            record: match problem {
                Some(p) => Err(p),
                None => IoData::siso(&u, &y).map_err(|e| format!("{name}: experiment {id}: {e}")),
            },
            id,
        })
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
            match parse(&text, "data.csv", "data") {
                Ok(records) => {
                    for r in records {
                        if let Err(problem) = r.record {
                            prop_assert!(problem.starts_with("data.csv: "), "{problem}");
                        }
                    }
                }
                Err(problem) => prop_assert!(problem.starts_with("data.csv: "), "{problem}"),
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
            let records = parse(&text, "f.csv", "f").expect("valid text");
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
            let records = parse(&text, "f.csv", "f").expect("valid header");
            for (e, record) in records.iter().enumerate() {
                if e == victim {
                    let problem = record.record.as_ref().expect_err("the bad record fails");
                    let name = ["u", "y"][column];
                    let expected = format!("f.csv: row {expected_row}, column {name}: '{token}'");
                    prop_assert!(problem.starts_with(&expected), "{} vs {}", problem, expected);
                } else {
                    prop_assert!(record.record.is_ok());
                }
            }
        }
    }

    #[test]
    fn headers_and_ragged_rows_are_rejected_with_their_row() {
        let problem = |text: &str| parse(text, "f.csv", "f").err().unwrap_or_default();
        assert_eq!(
            problem("\n \n"),
            "f.csv: the file is empty; expected a header u,y or experiment,u,y"
        );
        assert!(problem("t,y\n1,2\n").starts_with("f.csv: row 1: header 't,y'"));
        assert_eq!(
            problem("u,y\n1,2\n\n3\n"),
            "f.csv: row 4: 1 values, the header has 2"
        );
        let records = parse("u,y\n1,2\n3,4\n", "f.csv", "f").expect("valid");
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
}
