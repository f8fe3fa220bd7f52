//! A model file's `[input]`: the source's own design, or a fixed input
//! (values, or a measured record's columns) the model file hands over.

use std::path::{Path, PathBuf};

use toml::Spanned;
use twostage_models::InputSignal;

use super::locator::Locator;
use super::locator::Signals;
use super::raw::RawFile;
use super::raw::RawInput;
use super::{CommandInput, ModelFile, ModelSource};
use crate::error::{Error, Result};

impl Locator<'_> {
    /// The inputs a source needs are given: an FMU's time unit and its
    /// inputs' design, and an `[input]` only where `[signals]` names
    /// inputs (`measured`: the file gives a measured input).
    pub(super) fn check_inputs(
        &self,
        raw: &RawFile,
        source: &ModelSource,
        signals: &Signals,
        measured: bool,
    ) -> Result<()> {
        if let (ModelSource::Fmu { .. }, None) = (
            source,
            raw.signals
                .as_ref()
                .and_then(|s| s.get_ref().sample_time.as_ref()),
        ) {
            return Err(self.error(
                raw.signals.as_ref().map(Spanned::span),
                "signals.sample_time",
                "an FMU runs in its own time unit: give the time between samples, \
                 sample_time = T"
                    .into(),
            ));
        }
        let designed = match source {
            ModelSource::Fmu { input, .. } => Some((input, "the FMU's inputs")),
            ModelSource::Equations { input, .. } => Some((input, "the equations' inputs")),
            _ => None,
        };
        if let Some((input, whose)) = designed {
            let span = raw.signals.as_ref().map(Spanned::span);
            if input.is_none() && !measured && !signals.inputs.is_empty() {
                return Err(self.error(
                    span,
                    "signals.inputs",
                    format!(
                        "{whose} need a design: add an [input] (white, chicane or fixed, or a \
                         measured input file)"
                    ),
                ));
            }
            if let (Some(_), true) = (input, signals.inputs.is_empty()) {
                return Err(self.error(
                    raw.input.as_ref().map(Spanned::span),
                    "input",
                    "[input] drives the measured inputs, but [signals] names none".into(),
                ));
            }
        }
        let fixes_input = matches!(source, ModelSource::Command { input: Some(_), .. }) || measured;
        if fixes_input && signals.inputs.is_empty() {
            return Err(self.error(
                raw.input.as_ref().map(Spanned::span),
                "input",
                "[input] gives the measured inputs, but [signals] names none".into(),
            ));
        }
        Ok(())
    }

    /// A measured input from a CSV `file` (`signal = "fixed"`), for a
    /// built-in or FMU source; `None` for any other `[input]` (the
    /// source's own design).
    pub(super) fn measured_input(
        &self,
        input: Option<&Spanned<RawInput>>,
    ) -> Result<Option<CommandInput>> {
        match input {
            Some(i) if i.get_ref().file.is_some() => self.command_input(i).map(Some),
            _ => Ok(None),
        }
    }

    /// A command's fixed input: `values` for every input signal, or a
    /// CSV `file` whose columns are named as the model's inputs.
    pub(super) fn command_input(&self, input: &Spanned<RawInput>) -> Result<CommandInput> {
        let raw = input.get_ref();
        let fixed_only = || {
            self.error(
                Some(raw.signal.span()),
                "input.signal",
                "a command is handed one input for every experiment: give signal = \"fixed\" \
                 with its values, or with file = \"record.csv\" (a measured input)"
                    .into(),
            )
        };
        if raw.signal.get_ref() != "fixed" {
            return Err(fixed_only());
        }
        self.window_needs_a_file(raw)?;
        match (&raw.file, &raw.values) {
            (Some(file), None) if raw.sd.is_none() && raw.amplitude.is_none() => {
                if let Some(rows) = &raw.rows {
                    let [first, last] = *rows.get_ref();
                    if first == 0 || last < first {
                        return Err(self.error(
                            Some(rows.span()),
                            "input.rows",
                            format!(
                                "[{first}, {last}]: give the first and last data rows to read, \
                                 counted from 1 after the header, first <= last"
                            ),
                        ));
                    }
                }
                Ok(CommandInput::File {
                    path: PathBuf::from(file.get_ref()),
                    line: self.line(file.span().start),
                    columns: raw.columns.as_ref().map(|c| c.get_ref().clone()),
                    rows: raw.rows.as_ref().map(|r| *r.get_ref()),
                })
            }
            (Some(file), _) => Err(self.error(
                Some(file.span()),
                "input.file",
                "a fixed input takes either values or a file, not both".into(),
            )),
            (None, _) => {
                let signal = self.input(input)?;
                if signal.is_fixed() {
                    Ok(CommandInput::Values(signal))
                } else {
                    Err(fixed_only())
                }
            }
        }
    }

    /// `columns` and `rows` choose part of an input file: without one they
    /// would be ignored, so they are refused.
    fn window_needs_a_file(&self, raw: &RawInput) -> Result<()> {
        let window_without_file = raw
            .columns
            .as_ref()
            .map(|c| (c.span(), "input.columns"))
            .or(raw.rows.as_ref().map(|r| (r.span(), "input.rows")))
            .filter(|_| raw.file.is_none());
        match window_without_file {
            Some((span, key)) => Err(self.error(
                Some(span),
                key,
                "chooses part of an input file: give file = \"record.csv\" too".into(),
            )),
            None => Ok(()),
        }
    }

    pub(super) fn input(&self, input: &Spanned<RawInput>) -> Result<InputSignal> {
        let raw = input.get_ref();
        self.window_needs_a_file(raw)?;
        let kind = raw.signal.get_ref().as_str();
        let here = || Some(input.span());
        let (needed, signal) = match kind {
            "white" => ("sd", raw.sd.map(InputSignal::white_gaussian)),
            "chicane" => ("amplitude", raw.amplitude.map(InputSignal::chicane)),
            "fixed" => ("values", raw.values.clone().map(InputSignal::fixed)),
            other => {
                return Err(self.error(
                    Some(raw.signal.span()),
                    "input.signal",
                    format!("unknown signal '{other}': use \"white\", \"chicane\" or \"fixed\""),
                ));
            }
        };
        let extra = [
            ("sd", raw.sd.is_some()),
            ("amplitude", raw.amplitude.is_some()),
            ("values", raw.values.is_some()),
        ]
        .into_iter()
        .find(|(key, given)| *given && *key != needed);
        if let Some((key, _)) = extra {
            return Err(self.error(
                here(),
                &format!("input.{key}"),
                format!("a \"{kind}\" input takes {needed} only"),
            ));
        }
        signal
            .ok_or_else(|| {
                self.error(
                    here(),
                    &format!("input.{needed}"),
                    format!("a \"{kind}\" input needs {needed}"),
                )
            })?
            .map_err(|e| self.error(here(), "input", e.to_string()))
    }
}

impl ModelFile {
    /// The measured input a built-in or FMU source is handed, if the file
    /// names one.
    pub(super) fn measured_record(&self) -> Result<Option<twostage_models::IoData>> {
        self.measured_input
            .as_ref()
            .map(|input| self.fixed_record(input, None))
            .transpose()
    }

    /// The record of the file's shape whose inputs are the fixed ones
    /// (the outputs are not read).
    pub(super) fn fixed_record(
        &self,
        input: &CommandInput,
        dir: Option<&Path>,
    ) -> Result<twostage_models::IoData> {
        let mut record = self.spec.new_record();
        match input {
            CommandInput::Values(signal) => {
                // A fixed signal draws nothing: any stream serves.
                let mut rng = twostage_models::experiment_rng(0, 0);
                for j in 0..record.n_inputs() {
                    signal
                        .fill(self.spec.sample_time(), &mut rng, record.input_mut(j))
                        .map_err(|e| Error::ModelFile {
                            file: self.origin.clone(),
                            line: None,
                            key: "input.values".into(),
                            message: e.to_string(),
                        })?;
                }
            }
            CommandInput::File {
                path,
                line,
                columns: chosen,
                rows,
            } => {
                let path = match dir {
                    Some(dir) if path.is_relative() => dir.join(path),
                    _ => path.clone(),
                };
                let names = chosen.as_deref().unwrap_or(self.spec.input_names());
                let error = |key: &str, message: String| Error::ModelFile {
                    file: self.origin.clone(),
                    line: Some(*line),
                    key: key.into(),
                    message,
                };
                if names.len() != self.spec.input_names().len() {
                    return Err(error(
                        "input.columns",
                        format!(
                            "{} column(s) for the model's {} input(s) ({}): give one per input, \
                             in their order",
                            names.len(),
                            self.spec.input_names().len(),
                            self.spec.input_names().join(", ")
                        ),
                    ));
                }
                let mut columns = crate::csv_rows::read_columns(&path, names)
                    .map_err(|message| error("input.file", message))?;
                if let Some([first, last]) = *rows {
                    let available = columns.first().map_or(0, Vec::len);
                    if last > available {
                        return Err(error(
                            "input.rows",
                            format!(
                                "[{first}, {last}] lies outside {}, whose data rows are 1 to \
                                 {available}",
                                path.display()
                            ),
                        ));
                    }
                    for column in &mut columns {
                        *column = column[first - 1..last].to_vec();
                    }
                }
                let n = self.spec.n_samples();
                for (j, column) in columns.iter().enumerate() {
                    if column.len() != n {
                        return Err(Error::ModelFile {
                            file: self.origin.clone(),
                            line: Some(*line),
                            key: "input.file".into(),
                            message: format!(
                                "{} holds {} samples of {}; [signals] says samples = {n}: give \
                                 a record of that length or change samples",
                                path.display(),
                                column.len(),
                                self.spec.input_names()[j]
                            ),
                        });
                    }
                    record.input_mut(j).copy_from_slice(column);
                }
            }
        }
        Ok(record)
    }
}
