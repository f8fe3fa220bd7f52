//! CSV rows as the project's readers take them, on the csv crate: fields
//! trimmed, quotes honoured, blank lines skipped, each row with the line
//! it starts on (1-based), so every message can name it.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::io::Read;
use std::rc::Rc;

/// Line breaks (`\r` and `\n`, by byte offset) not yet counted: the csv
/// crate says where a record's parse began, which is before any blank
/// lines it skipped, so the rows' true lines are counted here.
type Breaks = Rc<RefCell<VecDeque<(u64, u8)>>>;

/// A reader that notes the offset of every line break it passes on.
struct NotingBreaks<R> {
    inner: R,
    offset: u64,
    breaks: Breaks,
}

impl<R: Read> Read for NotingBreaks<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let mut breaks = self.breaks.borrow_mut();
        for (i, b) in buf[..n].iter().enumerate() {
            if *b == b'\n' || *b == b'\r' {
                breaks.push_back((self.offset + i as u64, *b));
            }
        }
        self.offset += n as u64;
        Ok(n)
    }
}

/// A user's CSV file that cannot be read as asked: the file, the row and
/// column where the problem is (when it has one), and what is wrong and
/// what to do. Rows are counted as the file's lines, the header's being 1.
///
/// ```
/// use twostage_sources::csv_rows::DataFileError;
/// let e = DataFileError::at("runs.csv", 4, "'x' is not a finite number").in_column("y");
/// assert_eq!(e.to_string(), "runs.csv: row 4, column y: 'x' is not a finite number");
/// assert_eq!(e.row, Some(4));
/// ```
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{file}{}{}: {message}",
    row.map_or_else(String::new, |r| format!(": row {r}")),
    column.as_ref().map_or_else(String::new, |c| format!(", column {c}"))
)]
pub struct DataFileError {
    /// The file, as it was named.
    pub file: String,
    /// The row (the file's line, from 1) the problem is on, when it is on one.
    pub row: Option<usize>,
    /// The column the problem is in, when it is in one.
    pub column: Option<String>,
    /// What is wrong, and what to do.
    pub message: String,
}

impl DataFileError {
    /// A problem with the file as a whole (it cannot be opened, it is empty).
    pub fn whole(file: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            file: file.into(),
            row: None,
            column: None,
            message: message.into(),
        }
    }

    /// A problem on one row of the file.
    pub fn at(file: impl Into<String>, row: usize, message: impl Into<String>) -> Self {
        Self {
            row: Some(row),
            ..Self::whole(file, message)
        }
    }

    /// The same problem, placed in a column of its row.
    #[must_use]
    pub fn in_column(self, column: impl Into<String>) -> Self {
        Self {
            column: Some(column.into()),
            ..self
        }
    }
}

/// Visit each row of `input` (the header first) with its line number and
/// its fields, in one reused record; stop at the first error `visit`
/// returns. Rows may have any number of fields: the caller says what it
/// expected.
///
/// ```
/// let mut rows = Vec::new();
/// twostage_sources::csv_rows::for_each_row(
///     "u, y\n\n1,\"2\"\n".as_bytes(),
///     |line, fields| {
///         rows.push((line, fields.iter().map(str::to_string).collect::<Vec<_>>()));
///         Ok::<(), String>(())
///     },
///     |line, e| format!("line {line:?}: {e}"),
/// )?;
/// assert_eq!(rows[0], (1, vec!["u".to_string(), "y".to_string()]));
/// assert_eq!(rows[1], (3, vec!["1".to_string(), "2".to_string()]));
/// # Ok::<(), String>(())
/// ```
///
/// # Errors
/// What `visit` returns, or what `unreadable` makes of a row that cannot
/// be read (bytes that are not UTF-8, a read that fails), with its line
/// when known.
pub fn for_each_row<R: Read, E>(
    input: R,
    mut visit: impl FnMut(usize, &csv::StringRecord) -> Result<(), E>,
    unreadable: impl Fn(Option<usize>, String) -> E,
) -> Result<(), E> {
    let breaks: Breaks = Rc::default();
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(NotingBreaks {
            inner: input,
            offset: 0,
            breaks: Rc::clone(&breaks),
        });
    let mut record = csv::StringRecord::new();
    // Line breaks counted so far: the line of a row is one more than the
    // breaks before its first byte.
    let mut counted = 0usize;
    let mut line_at = |start: u64| -> usize {
        let mut start = start;
        let mut breaks = breaks.borrow_mut();
        while let Some(&(offset, byte)) = breaks.front() {
            if offset > start {
                break;
            }
            // A break at the row's start is a blank line the csv crate
            // skipped: the row begins after it.
            if offset == start {
                start += 1;
            }
            counted += usize::from(byte == b'\n');
            breaks.pop_front();
        }
        counted + 1
    };
    loop {
        match reader.read_record(&mut record) {
            Ok(false) => return Ok(()),
            Ok(true) => {
                let line = record.position().map_or(0, |p| line_at(p.byte()));
                // A line of blanks reads as one empty field: skip it as the
                // csv crate skips an empty line.
                if record.len() == 1 && record[0].is_empty() {
                    continue;
                }
                visit(line, &record)?;
            }
            Err(e) => {
                let line = e.position().map(|p| line_at(p.byte()));
                return Err(unreadable(line, e.to_string()));
            }
        }
    }
}

/// The shortest text that parses back to exactly `v`: plain decimals for
/// everyday magnitudes, scientific notation for very small or large ones.
/// Every number a table of estimates or records writes goes through it.
///
/// ```
/// use twostage_sources::csv_rows::format_f64;
/// assert_eq!(format_f64(0.5), "0.5");
/// assert_eq!(format_f64(-4.66933843093e-20), "-4.66933843093e-20");
/// ```
pub fn format_f64(v: f64) -> String {
    let magnitude = v.abs();
    if v == 0.0 || (1e-5..1e16).contains(&magnitude) || !v.is_finite() {
        // Display prints the shortest round-trip digits, never an exponent.
        format!("{v}")
    } else {
        // LowerExp also prints the shortest round-trip digits.
        format!("{v:e}")
    }
}

/// One row of CSV text: the fields joined by commas, each quoted only
/// where it must be (a comma, a quote, a line break), and a line break.
///
/// ```
/// use twostage_sources::csv_rows::row;
/// assert_eq!(row(["experiment", "u", "y"]), "experiment,u,y\n");
/// assert_eq!(row(["a,b", "1"]), "\"a,b\",1\n");
/// ```
pub fn row<I, S>(fields: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<[u8]>,
{
    let mut writer = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(Vec::new());
    // Writing to memory cannot fail; an empty row would be the only loss.
    let _ = writer.write_record(fields);
    String::from_utf8(writer.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// The columns named `names` of the CSV file at `path` (a header row,
/// then numbers; other columns are ignored), each as a vector of its
/// values.
///
/// ```
/// let dir = std::env::temp_dir().join("twostage-read-columns-doc");
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("record.csv");
/// std::fs::write(&path, "t,u,y\n0,1.5,9\n1,-2,9\n").unwrap();
/// let columns = twostage_sources::csv_rows::read_columns(&path, &["u".to_string()])?;
/// assert_eq!(columns, [vec![1.5, -2.0]]);
/// let missing = twostage_sources::csv_rows::read_columns(&path, &["v".to_string()]);
/// assert!(missing.unwrap_err().message.starts_with("no column `v`"));
/// # Ok::<(), twostage_sources::csv_rows::DataFileError>(())
/// ```
///
/// # Errors
/// A file that cannot be read, a missing column, or a value that is not a
/// finite number, named by file, row and column.
pub fn read_columns(
    path: &std::path::Path,
    names: &[String],
) -> Result<Vec<Vec<f64>>, DataFileError> {
    let file = path.display().to_string();
    let reader =
        std::fs::File::open(path).map_err(|e| DataFileError::whole(&file, e.to_string()))?;
    let mut at: Option<Vec<usize>> = None;
    let mut columns = vec![Vec::new(); names.len()];
    for_each_row(
        std::io::BufReader::new(reader),
        |line, fields| {
            let Some(at) = &at else {
                let header: Vec<&str> = fields.iter().collect();
                at = Some(
                    names
                        .iter()
                        .map(|name| {
                            header.iter().position(|h| h == name).ok_or_else(|| {
                                DataFileError::at(
                                    &file,
                                    line,
                                    format!(
                                        "no column `{name}` (the header has {})",
                                        excerpt(&header.join(", "))
                                    ),
                                )
                            })
                        })
                        .collect::<Result<_, _>>()?,
                );
                return Ok(());
            };
            for ((column, &c), name) in columns.iter_mut().zip(at).zip(names) {
                let cell = fields.get(c).unwrap_or("");
                let value = cell
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        DataFileError::at(
                            &file,
                            line,
                            format!("{:?} is not a finite number", excerpt(cell)),
                        )
                        .in_column(name)
                    })?;
                column.push(value);
            }
            Ok(())
        },
        |line, e| DataFileError {
            row: line,
            ..DataFileError::whole(&file, e)
        },
    )?;
    Ok(columns)
}

/// Characters of a user's text an error message quotes.
pub const EXCERPT_CHARACTERS: usize = 200;

/// `text` as an error message quotes it: whole up to
/// [`EXCERPT_CHARACTERS`], else its beginning and how long it was, so that
/// a hostile line (a header of a million columns) cannot make a message of
/// megabytes.
///
/// ```
/// use twostage_sources::csv_rows::excerpt;
/// assert_eq!(excerpt("u,y"), "u,y");
/// let wide = vec!["z"; 1000].join(",");
/// assert!(excerpt(&wide).ends_with("... (1999 characters)"));
/// ```
pub fn excerpt(text: &str) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(EXCERPT_CHARACTERS) {
        None => std::borrow::Cow::Borrowed(text),
        Some((cut, _)) => std::borrow::Cow::Owned(format!(
            "{}... ({} characters)",
            &text[..cut],
            text.chars().count()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_value_reads_back_to_the_same_bits() {
        let mut special = vec![
            0.0,
            -0.0,
            1.0,
            -1.1,
            0.1,
            1e-5,
            9.99e-6,
            1e16,
            1e15,
            f64::MIN_POSITIVE,
            f64::MAX,
            5e-324,
            -4.66933843093e-20,
            1.22464679915e-17,
        ];
        // Bit patterns of every exponent (splitmix64's sequence).
        let mut state: u64 = 1;
        for _ in 0..20_000 {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            let v = f64::from_bits(z ^ (z >> 31));
            if v.is_finite() {
                special.push(v);
            }
        }
        for v in special {
            let text = format_f64(v);
            let back: f64 = text.parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{v:e} printed as {text}");
        }
    }

    fn rows(text: &str) -> Result<Vec<(usize, Vec<String>)>, String> {
        let mut out = Vec::new();
        for_each_row(
            text.as_bytes(),
            |line, fields| {
                out.push((line, fields.iter().map(str::to_string).collect()));
                Ok(())
            },
            |line, e| format!("{line:?}: {e}"),
        )?;
        Ok(out)
    }

    #[test]
    fn rows_after_blank_lines_keep_their_line() {
        let lines =
            |text: &str| -> Vec<usize> { rows(text).unwrap().iter().map(|(l, _)| *l).collect() };
        assert_eq!(lines("u,y\n1,2\n\n3\n"), [1, 2, 4]);
        assert_eq!(lines("u,y\r\n1,2\r\n\r\n\r\n3\r\n4,5"), [1, 2, 5, 6]);
        assert_eq!(lines("\n\nu\n\"a\nb\"\n\nc\n"), [3, 4, 7]);
    }

    #[test]
    fn lines_are_counted_through_blank_lines_and_quotes() {
        let text = "a,b\n\n  \n1, 2\n\"x\ny\",3\n4,5,6\n";
        let got = rows(text).unwrap();
        let lines: Vec<usize> = got.iter().map(|(l, _)| *l).collect();
        assert_eq!(lines, [1, 4, 5, 7]);
        assert_eq!(got[1].1, ["1", "2"]);
        assert_eq!(got[2].1, ["x\ny", "3"]);
        assert_eq!(got[3].1, ["4", "5", "6"], "the caller checks the width");
    }

    #[test]
    fn bytes_that_are_not_text_name_their_line() {
        let e = {
            let mut bytes = b"a,b\n1,2\n".to_vec();
            bytes.extend_from_slice(&[0xff, b',', b'1', b'\n']);
            let mut count = 0;
            for_each_row(
                bytes.as_slice(),
                |_, _| {
                    count += 1;
                    Ok(())
                },
                |line, e| format!("{line:?}: {e}"),
            )
            .unwrap_err()
        };
        assert!(e.starts_with("Some(3)"), "{e}");
    }

    #[test]
    fn rows_quote_only_where_they_must_and_read_back() {
        let text = row(["plain", "with,comma", "with \"quote\""]);
        assert_eq!(text, "plain,\"with,comma\",\"with \"\"quote\"\"\"\n");
        assert_eq!(
            rows(&text).unwrap()[0].1,
            ["plain", "with,comma", "with \"quote\""]
        );
    }
}
