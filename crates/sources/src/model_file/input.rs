//! A model file's `[input]`: the source's own design, or a fixed input
//! (values, or a measured record's columns) the model file hands over.

use std::path::PathBuf;

use toml::Spanned;
use twostage_models::InputSignal;

use super::CommandInput;
use super::locator::Locator;
use super::raw::RawInput;
use crate::error::Result;

impl Locator<'_> {
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
        match (&raw.file, &raw.values) {
            (Some(file), None) if raw.sd.is_none() && raw.amplitude.is_none() => {
                Ok(CommandInput::File {
                    path: PathBuf::from(file.get_ref()),
                    line: self.line(file.span().start),
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

    pub(super) fn input(&self, input: &Spanned<RawInput>) -> Result<InputSignal> {
        let raw = input.get_ref();
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
