//! Files of parameter values, as `twostage estimate` writes them: an
//! optional `experiment` column and a column per parameter, named as the
//! model names them (other columns ignored). What `estimate --at` checks
//! and `simulate --at` runs the model at.

use std::path::Path;

use crate::csv_rows::for_each_row;

/// The rows of a file of parameter values.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterRows {
    /// Each row's experiment (the `experiment` column, or the row's
    /// number counted from 1 when there is none) and its values, in the
    /// model's parameter order.
    pub rows: Vec<(String, Vec<f64>)>,
    /// The rows left out because every parameter cell is empty (a record
    /// `estimate` could not estimate), each said as file, line and
    /// experiment.
    pub skipped: Vec<String>,
}

/// The rows of the parameter-value file at `path`, read with the model's
/// parameter `names`.
///
/// ```
/// use twostage_sources::parameter_values;
/// let dir = std::env::temp_dir().join(format!("values-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let path = dir.join("estimates.csv");
/// std::fs::write(&path, "experiment,theta,theta_lo\n7,0.25,0.2\n8,,\n")?;
/// let read = parameter_values::read(&path, &["theta".to_string()])?;
/// assert_eq!(read.rows, vec![("7".to_string(), vec![0.25])]);
/// assert_eq!(read.skipped.len(), 1, "experiment 8 has no estimate");
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// The file cannot be opened, a parameter's column is missing, a value is
/// not a finite number (file, line, column), or no row holds values: each
/// message says which and what the file should hold.
pub fn read(path: &Path, names: &[String]) -> Result<ParameterRows, String> {
    let file = path.display().to_string();
    let reader = std::fs::File::open(path).map_err(|e| format!("{file}: {e}"))?;
    let mut columns: Option<(Option<usize>, Vec<usize>)> = None;
    let mut read = ParameterRows {
        rows: Vec::new(),
        skipped: Vec::new(),
    };
    for_each_row(
        std::io::BufReader::new(reader),
        |line, fields| -> Result<(), String> {
            let Some((id_column, theta_columns)) = &columns else {
                let header: Vec<&str> = fields.iter().collect();
                let find = |name: &str| header.iter().position(|h| *h == name);
                let theta_columns = names
                    .iter()
                    .map(|n| {
                        find(n).ok_or_else(|| {
                            format!(
                                "{file}, line {line}: no column `{n}`; an estimate CSV names \
                                 the model's parameters ({}) in its header, as `twostage \
                                 estimate` writes it",
                                names.join(", ")
                            )
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                columns = Some((find("experiment"), theta_columns));
                return Ok(());
            };
            let id = id_column
                .and_then(|c| fields.get(c))
                .map_or_else(|| (read.rows.len() + 1).to_string(), str::to_string);
            let cells: Vec<&str> = theta_columns
                .iter()
                .map(|&c| fields.get(c).unwrap_or(""))
                .collect();
            if cells.iter().all(|c| c.is_empty()) {
                read.skipped.push(format!(
                    "{file}, line {line} (experiment {id}) has no estimate: skipped"
                ));
                return Ok(());
            }
            let theta = cells
                .iter()
                .zip(names)
                .map(|(cell, name)| {
                    cell.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            format!(
                                "{file}, line {line}, column {name}: {cell:?} is not a finite \
                                 number"
                            )
                        })
                })
                .collect::<Result<Vec<_>, _>>()?;
            read.rows.push((id, theta));
            Ok(())
        },
        |line, e| format!("{file}, line {line:?}: {e}"),
    )?;
    if read.rows.is_empty() {
        return Err(format!(
            "{file} holds no parameter values: a header naming the parameters ({}) and a row \
             of values under it",
            names.join(", ")
        ));
    }
    Ok(read)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn written(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("parameter-values-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    fn names() -> Vec<String> {
        vec!["pK1".into(), "pK2".into()]
    }

    /// Columns are found by name in any order; rows without an
    /// `experiment` column are numbered from 1.
    #[test]
    fn columns_are_matched_by_name_and_rows_numbered_without_ids() {
        let path = written("reordered.csv", "pK2,note,pK1\n2.5,a,1.5\n-1e-3,b,3\n");
        let read = read(&path, &names()).unwrap();
        assert_eq!(
            read.rows,
            vec![
                ("1".to_string(), vec![1.5, 2.5]),
                ("2".to_string(), vec![3.0, -1e-3])
            ]
        );
    }

    /// Every refusal names the file, the line and the column.
    #[test]
    fn a_missing_column_a_bad_number_and_an_empty_file_are_named() {
        let missing = read(&written("missing.csv", "pK1\n1\n"), &names()).unwrap_err();
        assert!(missing.contains("line 1: no column `pK2`"), "{missing}");
        let bad = read(&written("bad.csv", "pK1,pK2\n1,2\n1,inf\n"), &names()).unwrap_err();
        assert!(bad.contains("line 3, column pK2: \"inf\""), "{bad}");
        let empty = read(&written("empty.csv", "pK1,pK2\n,\n"), &names()).unwrap_err();
        assert!(empty.contains("holds no parameter values"), "{empty}");
    }
}
