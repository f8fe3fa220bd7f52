//! A design's `spectrum` table or `like` record: the relative amplitudes
//! of a multisine's or a band noise's lines.

use std::path::PathBuf;

use twostage_models::Spectrum;

use super::locator::Locator;
use super::raw::RawInput;
use crate::csv_rows::read_columns;
use crate::error::Result;

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
