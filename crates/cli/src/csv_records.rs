//! Reading records from CSV: `u,y` (one record) or `experiment,u,y` (many,
//! long format). Every problem names the file, the row and the column.

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
    let stem = path
        .file_stem()
        .map_or_else(|| name.clone(), |s| s.to_string_lossy().into_owned());
    // Records in the order their experiment first appears.
    let mut order: Vec<String> = Vec::new();
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
        let id = if long {
            fields[0].to_string()
        } else {
            stem.clone()
        };
        let slot = match order.iter().position(|e| *e == id) {
            Some(slot) => slot,
            None => {
                order.push(id);
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
