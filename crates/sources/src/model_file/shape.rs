//! A design's `spectrum` table or `like` record: the relative amplitudes
//! of a multisine's or a band noise's lines.

use std::path::PathBuf;

use twostage_models::Spectrum;

use super::locator::Locator;
use super::raw::RawInput;
use crate::csv_rows::read_columns;
use crate::error::Result;

/// The largest file a `like` record is read from.
const MAX_LIKE_BYTES: u64 = 1 << 30;

impl Locator<'_> {
    /// The shape `[input]` gives its lines, if any: a `spectrum` table, or
    /// the spectrum of a measured record's column (`like`), read from the
    /// model file's folder.
    pub(super) fn spectrum(&self, raw: &RawInput) -> Result<Option<Spectrum>> {
        match (&raw.spectrum, &raw.like) {
            (None, None) => Ok(None),
            (Some(_), Some(like)) => Err(self.error(
                Some(like.span()),
                "input.like",
                "give the lines' shape once: a spectrum table or a record to look like, not both"
                    .into(),
            )),
            (Some(table), None) => Spectrum::table(table.get_ref().clone())
                .map(Some)
                .map_err(|e| self.error(Some(table.span()), "input.spectrum", e.to_string())),
            (None, Some(like)) => {
                let like = like.get_ref();
                let named = PathBuf::from(like.file.get_ref());
                let path = match self.folder {
                    Some(folder) if named.is_relative() => folder.join(&named),
                    _ => named,
                };
                // A device or a folder named by mistake would be read
                // without end, or not at all: a record is a file of a
                // record's size.
                let size = std::fs::metadata(&path)
                    .ok()
                    .filter(|m| m.is_file())
                    .map(|m| m.len());
                if let Some(size) = size.filter(|s| *s > MAX_LIKE_BYTES) {
                    return Err(self.error(
                        Some(like.file.span()),
                        "input.like.file",
                        format!(
                            "{}: a file of {}, where a record to look like takes at most {}: \
                             give the rows of one record (rows = [first, last]) in a file of \
                             its own",
                            path.display(),
                            crate::readable_bytes(size as f64),
                            crate::readable_bytes(MAX_LIKE_BYTES as f64)
                        ),
                    ));
                }
                if size.is_none() && path.exists() {
                    return Err(self.error(
                        Some(like.file.span()),
                        "input.like.file",
                        format!(
                            "{}: not a file: name the CSV file of a record",
                            path.display()
                        ),
                    ));
                }
                let column = like.column.get_ref().clone();
                let mut samples = read_columns(&path, std::slice::from_ref(&column))
                    .map_err(|e| {
                        let (span, key) = if e.message.starts_with("no column") {
                            (like.column.span(), "input.like.column")
                        } else {
                            (like.file.span(), "input.like.file")
                        };
                        self.error(Some(span), key, e.to_string())
                    })?
                    .pop()
                    .unwrap_or_default();
                if let Some(rows) = &like.rows {
                    let [first, last] = *rows.get_ref();
                    if first == 0 || last < first || last > samples.len() {
                        return Err(self.error(
                            Some(rows.span()),
                            "input.like.rows",
                            format!(
                                "[{first}, {last}]: give the first and last data rows to read, \
                                 counted from 1 after the header, first <= last <= {} (the \
                                 rows {} has)",
                                samples.len(),
                                path.display()
                            ),
                        ));
                    }
                    samples.truncate(last);
                    samples.drain(..first - 1);
                }
                Spectrum::like(&samples).map(Some).map_err(|e| {
                    self.error(
                        Some(like.column.span()),
                        "input.like.column",
                        format!("column `{column}` of {}: {e}", path.display()),
                    )
                })
            }
        }
    }
}
