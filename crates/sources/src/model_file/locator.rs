//! Checking a parsed model file, every mistake named by its line and key.

use std::ops::Range;
use std::path::PathBuf;

use toml::Spanned;
use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;
use twostage_fmi::InterfaceKind;
use twostage_models::{BuiltinModel, BuiltinOverrides, ModelSpec, PROTOCOL_VERSION};

use super::raw::*;
use super::{DEFAULT_PRESET_SIMULATIONS, ModelSource};
use crate::error::{Error, Result};
use crate::preset::Preset;
use crate::readable_bytes;

/// The checked signals.
pub(super) struct Signals {
    pub(super) inputs: Vec<String>,
    pub(super) outputs: Vec<String>,
    pub(super) samples: usize,
    pub(super) sample_time: f64,
}

/// How a model file runs its FMU.
struct FmuRun {
    step_divisor: usize,
    start_time: f64,
    /// Start values of the FMU's variables, by name.
    starts: Vec<(String, f64)>,
}

/// Turns byte spans into lines and builds errors.
pub(super) struct Locator<'t> {
    pub(super) text: &'t str,
    pub(super) origin: &'t str,
    /// The model file's folder, where the files it names are found
    /// (`None`: a text parsed alone, its files relative to the working
    /// folder).
    pub(super) folder: Option<&'t std::path::Path>,
    /// Where each line break is, found once: a file names a line per
    /// parameter and signal, and counting from the start for each made
    /// reading a file of many names take time in their square.
    breaks: std::cell::OnceCell<Vec<usize>>,
}

impl<'t> Locator<'t> {
    pub(super) fn new(text: &'t str, origin: &'t str) -> Self {
        Self {
            text,
            origin,
            folder: None,
            breaks: std::cell::OnceCell::new(),
        }
    }

    /// The same, the files the model file names found in `folder`.
    pub(super) fn beside(self, folder: Option<&'t std::path::Path>) -> Self {
        Self { folder, ..self }
    }

    /// The line (from 1) of byte `offset`.
    pub(super) fn line(&self, offset: usize) -> usize {
        let breaks = self.breaks.get_or_init(|| {
            self.text
                .bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(k, _)| k)
                .collect()
        });
        1 + breaks.partition_point(|&k| k < offset.min(self.text.len()))
    }

    /// The dotted key whose value starts at byte `offset` (`input.hold`,
    /// `parameter.prior.sigma` inside an inline table), read from the
    /// text: the names before the `=` signs on its line that lead to it,
    /// under the nearest table header above it; empty where there is none
    /// (a key of its own, a value on a line of its own in a long array).
    pub(super) fn key_at(&self, offset: usize) -> String {
        let Some(before) = self.text.get(..offset.min(self.text.len())) else {
            return String::new();
        };
        let line_start = before.rfind('\n').map_or(0, |k| k + 1);
        let segment = &before[line_start..];
        // The inline tables still open at the value, and after the last of
        // them the value's own key.
        let mut open: Vec<usize> = Vec::new();
        for (k, c) in segment.char_indices() {
            match c {
                '{' => open.push(k),
                '}' => {
                    open.pop();
                }
                _ => {}
            }
        }
        let mut names: Vec<String> = open
            .iter()
            .map(|&k| name_before_equals(&segment[..k]))
            .collect();
        let innermost = &segment[open.last().map_or(0, |k| k + 1)..];
        names.push(name_before_equals(innermost));
        if names.iter().any(String::is_empty) {
            return String::new();
        }
        let table = before[..line_start]
            .lines()
            .rev()
            .map(str::trim)
            .find(|l| l.starts_with('['))
            .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim());
        if let Some(table) = table.filter(|t| !t.is_empty()) {
            names.insert(0, table.to_string());
        }
        names.join(".")
    }

    pub(super) fn error(&self, span: Option<Range<usize>>, key: &str, message: String) -> Error {
        Error::ModelFile {
            file: self.origin.to_string(),
            line: span.map(|s| self.line(s.start)),
            key: key.to_string(),
            message,
        }
    }

    pub(super) fn source(
        &self,
        source: Option<&Spanned<RawSource>>,
        noise: Option<&Spanned<RawNoise>>,
        input: Option<&Spanned<RawInput>>,
    ) -> Result<ModelSource> {
        let Some(source) = source else {
            if let Some(input) = input {
                return Err(self.error(
                    Some(input.span()),
                    "input",
                    "an [input] needs a [source] to drive; a file without one describes charts \
                     simulated elsewhere"
                        .into(),
                ));
            }
            return Ok(ModelSource::ChartsOnly);
        };
        let raw = source.get_ref();
        if let Some(fmu) = &raw.fmu {
            if raw.builtin.is_some() || raw.command.is_some() {
                return Err(self.one_source(source.span()));
            }
            return self.fmu(fmu, raw, noise, input);
        }
        if let Some((key, span)) = raw.fmu_key() {
            return Err(self.error(Some(span), key, "only an FMU source takes this key".into()));
        }
        if let Some(inputs) = noise.and_then(|n| n.get_ref().inputs.as_ref()) {
            return Err(self.error(
                Some(inputs.span()),
                "noise.inputs",
                "noise inputs drive an FMU's inputs: only an FMU source takes them".into(),
            ));
        }
        let name = match (&raw.builtin, &raw.command) {
            (Some(name), None) => name,
            (None, Some(command)) => return self.command(command, raw, noise, input),
            _ => return Err(self.one_source(source.span())),
        };
        if let Some(t) = &raw.timeout_seconds {
            return Err(self.error(
                Some(t.span()),
                "source.timeout_seconds",
                "a built-in model runs in this process: the timeout is for a command".into(),
            ));
        }
        if let Some(b) = &raw.batch {
            return Err(self.error(
                Some(b.span()),
                "source.batch",
                "a built-in model runs in this process: the batch is for a command".into(),
            ));
        }
        if let Some(p) = &raw.protocol {
            return Err(self.error(
                Some(p.span()),
                "source.protocol",
                "a built-in model runs in this process: the protocol is for a command".into(),
            ));
        }
        let model: BuiltinModel =
            name.get_ref()
                .parse()
                .map_err(|e: twostage_models::SimError| {
                    self.error(Some(name.span()), "source.builtin", e.to_string())
                })?;
        let noiseless = noise.is_some_and(|n| n.get_ref().model == Some(false));
        // A measured input from a file is handed over by the model file's
        // simulator (`measured_input`), not designed by the source.
        let input = input
            .filter(|i| i.get_ref().file.is_none())
            .map(|i| self.input(i))
            .transpose()?;
        Ok(ModelSource::Builtin {
            model,
            overrides: BuiltinOverrides {
                noiseless,
                n_samples: None,
                input,
            },
        })
    }

    pub(super) fn one_source(&self, span: Range<usize>) -> Error {
        self.error(
            Some(span),
            "source",
            "give one source: builtin = \"benchmark\" (or \"pacejka\"), command = \
             [\"python3\", \"sim.py\"] (docs/protocol.md), or fmu = \"model.fmu\" (docs/fmu.md)"
                .into(),
        )
    }

    pub(super) fn fmu(
        &self,
        fmu: &Spanned<String>,
        raw: &RawSource,
        noise: Option<&Spanned<RawNoise>>,
        input: Option<&Spanned<RawInput>>,
    ) -> Result<ModelSource> {
        if fmu.get_ref().trim().is_empty() {
            return Err(self.error(
                Some(fmu.span()),
                "source.fmu",
                "give the FMU's path, e.g. fmu = \"car.fmu\" (relative to this file)".into(),
            ));
        }
        for (key, span) in [
            (
                "source.timeout_seconds",
                raw.timeout_seconds.as_ref().map(Spanned::span),
            ),
            ("source.batch", raw.batch.as_ref().map(Spanned::span)),
        ] {
            if let Some(span) = span {
                return Err(self.error(
                    Some(span),
                    key,
                    "an FMU runs in this process: the key is for a command".into(),
                ));
            }
        }
        if let Some(noise) = noise.filter(|n| n.get_ref().model.is_some()) {
            return Err(self.error(
                Some(noise.span()),
                "noise.model",
                "`model` switches a built-in model's noise; give an FMU's noise as noise inputs"
                    .into(),
            ));
        }
        let interface = raw
            .interface
            .as_ref()
            .map(|i| {
                i.get_ref()
                    .parse::<InterfaceKind>()
                    .map_err(|e| self.error(Some(i.span()), "source.interface", e.to_string()))
            })
            .transpose()?;
        let FmuRun {
            step_divisor,
            start_time,
            starts,
        } = self.fmu_run(raw)?;
        let noise_inputs = self.fmu_noise_inputs(noise)?;
        Ok(ModelSource::Fmu {
            path: PathBuf::from(fmu.get_ref()),
            interface,
            step_divisor,
            start_time,
            starts,
            noise_inputs,
            input: input
                .filter(|i| i.get_ref().file.is_none())
                .map(|i| self.input(i))
                .transpose()?,
        })
    }

    /// How an FMU is run: its steps per sample, its start time, and the
    /// start values of its variables.
    fn fmu_run(&self, raw: &RawSource) -> Result<FmuRun> {
        let step_divisor = match &raw.step_divisor {
            None => 1,
            Some(d) => usize::try_from(*d.get_ref())
                .ok()
                .filter(|d| (1..=1 << 16).contains(d))
                .ok_or_else(|| {
                    self.error(
                        Some(d.span()),
                        "source.step_divisor",
                        format!("{}: give 1 to 65536 steps per sample", d.get_ref()),
                    )
                })?,
        };
        let start_time = match &raw.start_time {
            None => 0.0,
            Some(t) if t.get_ref().is_finite() => *t.get_ref(),
            Some(t) => {
                return Err(self.error(
                    Some(t.span()),
                    "source.start_time",
                    format!("{}: give a finite time", t.get_ref()),
                ));
            }
        };
        let starts: Vec<(String, f64)> = raw
            .start
            .as_ref()
            .map(|s| s.get_ref().iter().map(|(k, v)| (k.clone(), *v)).collect())
            .unwrap_or_default();
        if let Some((name, value)) = starts.iter().find(|(_, v)| !v.is_finite()) {
            return Err(self.error(
                raw.start.as_ref().map(Spanned::span),
                "source.start",
                format!("{name} = {value}: give a finite start value"),
            ));
        }
        Ok(FmuRun {
            step_divisor,
            start_time,
            starts,
        })
    }

    /// An FMU's noise inputs and their standard deviations, each named
    /// once.
    fn fmu_noise_inputs(&self, noise: Option<&Spanned<RawNoise>>) -> Result<Vec<(String, f64)>> {
        let mut noise_inputs: Vec<(String, f64)> = Vec::new();
        if let Some(list) = noise.and_then(|n| n.get_ref().inputs.as_ref()) {
            for n in list.get_ref() {
                let name = n.name.trim().to_string();
                if name.is_empty() || noise_inputs.iter().any(|(other, _)| *other == name) {
                    return Err(self.error(
                        Some(list.span()),
                        "noise.inputs",
                        format!("'{name}' is empty or named twice"),
                    ));
                }
                if !(n.sd.is_finite() && n.sd >= 0.0) {
                    return Err(self.error(
                        Some(list.span()),
                        "noise.inputs",
                        format!("{name}: sd = {} must be finite and >= 0", n.sd),
                    ));
                }
                noise_inputs.push((name, n.sd));
            }
        }
        Ok(noise_inputs)
    }

    /// Where the names a source must know were written.
    pub(super) fn name_lines(&self, raw: &RawFile) -> Vec<(String, &'static str, usize)> {
        let mut lines = Vec::new();
        for p in &raw.parameter {
            let name = p.get_ref().name.get_ref().trim().to_string();
            lines.push((
                name,
                "parameter.name",
                self.line(p.get_ref().name.span().start),
            ));
        }
        // In the order the FMU simulator checks them, so that a name given
        // two roles is placed at its second.
        let signals = raw.signals.as_ref().map(Spanned::get_ref);
        let at = |list: &Spanned<Vec<String>>| self.line(list.span().start);
        if let Some(list) = signals.and_then(|s| s.inputs.as_ref()) {
            lines.extend(
                list.get_ref()
                    .iter()
                    .map(|n| (n.clone(), "signals.inputs", at(list))),
            );
        }
        if let Some(inputs) = raw.noise.as_ref().and_then(|n| n.get_ref().inputs.as_ref()) {
            let line = self.line(inputs.span().start);
            lines.extend(
                inputs
                    .get_ref()
                    .iter()
                    .map(|n| (n.name.trim().to_string(), "noise.inputs", line)),
            );
        }
        if let Some(list) = signals.and_then(|s| s.outputs.as_ref()) {
            lines.extend(
                list.get_ref()
                    .iter()
                    .map(|n| (n.clone(), "signals.outputs", at(list))),
            );
        }
        if let Some(start) = raw.source.as_ref().and_then(|s| s.get_ref().start.as_ref()) {
            let line = self.line(start.span().start);
            lines.extend(
                start
                    .get_ref()
                    .keys()
                    .map(|n| (n.clone(), "source.start", line)),
            );
        }
        lines
    }

    pub(super) fn command(
        &self,
        command: &Spanned<Vec<String>>,
        raw: &RawSource,
        noise: Option<&Spanned<RawNoise>>,
        input: Option<&Spanned<RawInput>>,
    ) -> Result<ModelSource> {
        if command
            .get_ref()
            .first()
            .is_none_or(|c| c.trim().is_empty())
        {
            return Err(self.error(
                Some(command.span()),
                "source.command",
                "give the program and its arguments, e.g. [\"python3\", \"sim.py\"]".into(),
            ));
        }
        let protocol = match &raw.protocol {
            None => 1,
            Some(p) => u32::try_from(*p.get_ref())
                .ok()
                .filter(|v| (1..=PROTOCOL_VERSION).contains(v))
                .ok_or_else(|| {
                    self.error(
                        Some(p.span()),
                        "source.protocol",
                        format!(
                            "{}: give the protocol version the simulator speaks, 1 to \
                             {PROTOCOL_VERSION} (docs/protocol.md)",
                            p.get_ref()
                        ),
                    )
                })?,
        };
        let input = match input {
            None => None,
            Some(i) if protocol < 2 => {
                return Err(self.error(
                    Some(i.span()),
                    "input",
                    "a command speaking protocol 1 makes its own input and returns it with the \
                     outputs: leave [input] out, or say `protocol = 2` under [source] and serve \
                     version 2, which hands the simulator each experiment's input (fixed, or \
                     drawn by twostage from the design)"
                        .into(),
                ));
            }
            Some(i) => Some(self.command_input(i)?),
        };
        if let Some(noise) = noise.filter(|n| n.get_ref().model.is_some()) {
            return Err(self.error(
                Some(noise.span()),
                "noise.model",
                "`model` switches a built-in model's noise; a command's noise is its own".into(),
            ));
        }
        let timeout = match &raw.timeout_seconds {
            None => std::time::Duration::from_secs(60),
            Some(t) => std::time::Duration::try_from_secs_f64(*t.get_ref())
                .ok()
                .filter(|d| !d.is_zero())
                .ok_or_else(|| {
                    self.error(
                        Some(t.span()),
                        "source.timeout_seconds",
                        format!("{}: give a number of seconds > 0", t.get_ref()),
                    )
                })?,
        };
        let batch = match &raw.batch {
            None => 1,
            Some(b) => usize::try_from(*b.get_ref())
                .ok()
                .filter(|b| (1..=1 << 20).contains(b))
                .ok_or_else(|| {
                    self.error(
                        Some(b.span()),
                        "source.batch",
                        format!(
                            "{}: give the experiments per request, 1 to 2^20",
                            b.get_ref()
                        ),
                    )
                })?,
        };
        Ok(ModelSource::Command {
            command: command.get_ref().clone(),
            dir: None,
            timeout,
            batch,
            protocol,
            input,
        })
    }

    pub(super) fn signals(
        &self,
        raw: Option<&Spanned<RawSignals>>,
        base: Option<&ModelSpec>,
    ) -> Result<Signals> {
        let empty = RawSignals {
            inputs: None,
            outputs: None,
            samples: None,
            sample_time: None,
        };
        let s = raw.map_or(&empty, Spanned::get_ref);
        let whole = raw.map(Spanned::span);
        let inputs = self.signal_names(
            s.inputs.as_ref(),
            "signals.inputs",
            base.map(ModelSpec::input_names),
            whole.clone(),
        )?;
        let outputs = self.signal_names(
            s.outputs.as_ref(),
            "signals.outputs",
            base.map(ModelSpec::output_names),
            whole.clone(),
        )?;
        if outputs.is_empty() {
            return Err(self.error(
                whole,
                "signals.outputs",
                "at least one output: an estimator learns from what is measured".into(),
            ));
        }
        let samples = self.record_length(s.samples.as_ref(), base, whole.clone())?;
        let signals = inputs.len() + outputs.len();
        let most = MAX_RECORD_BYTES / (8 * signals);
        if samples > most {
            // In f64: samples x signals x 8 can overflow usize.
            let bytes = samples as f64 * signals as f64 * 8.0;
            return Err(self.error(
                s.samples.as_ref().map(Spanned::span).or(whole),
                "signals.samples",
                format!(
                    "{samples} samples of {signals} signal(s) would take {} for one record, \
                     which is held whole in memory (by each thread at once): at most {most} \
                     samples fit the {} a record may take; give a shorter record",
                    readable_bytes(bytes),
                    readable_bytes(MAX_RECORD_BYTES as f64)
                ),
            ));
        }
        let sample_time = self.sample_time(s.sample_time.as_ref(), base)?;
        if !(samples as f64 * sample_time).is_finite() {
            return Err(self.error(
                s.sample_time.as_ref().map(Spanned::span).or(whole),
                "signals.sample_time",
                format!(
                    "{samples} samples {sample_time:e} apart end beyond the largest time a number \
                     holds: give at most {:e}",
                    f64::MAX / samples as f64
                ),
            ));
        }
        Ok(Signals {
            inputs,
            outputs,
            samples,
            sample_time,
        })
    }

    /// The names of `[signals]`' `key` (`given`), or the built-in
    /// source's (`base`): renamed one for one, each its own.
    fn signal_names(
        &self,
        given: Option<&Spanned<Vec<String>>>,
        key: &str,
        base: Option<&[String]>,
        whole: Option<std::ops::Range<usize>>,
    ) -> Result<Vec<String>> {
        match (given, base) {
            (Some(list), Some(base)) if list.get_ref().len() != base.len() => Err(self.error(
                Some(list.span()),
                key,
                format!(
                    "the built-in source has {} ({}); rename them one for one",
                    base.len(),
                    base.join(", ")
                ),
            )),
            (Some(list), _) => {
                let mut seen: Vec<&String> = Vec::new();
                for n in list.get_ref() {
                    if n.trim().is_empty() || seen.contains(&n) {
                        return Err(self.error(
                            Some(list.span()),
                            key,
                            format!("'{n}' is empty or used twice: each signal needs its own name"),
                        ));
                    }
                    seen.push(n);
                }
                Ok(list.get_ref().clone())
            }
            (None, Some(base)) => Ok(base.to_vec()),
            (None, None) if key == "signals.inputs" => Ok(Vec::new()),
            (None, None) => Err(self.error(
                whole,
                key,
                "name the measured outputs, e.g. outputs = [\"y\"]".into(),
            )),
        }
    }

    /// `[signals] samples`, or the built-in source's record length (at
    /// least 1; the record's size is checked by [`Self::signals`]).
    fn record_length(
        &self,
        given: Option<&Spanned<i64>>,
        base: Option<&ModelSpec>,
        whole: Option<std::ops::Range<usize>>,
    ) -> Result<usize> {
        match (given, base) {
            (Some(n), _) => usize::try_from(*n.get_ref())
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| {
                    self.error(
                        Some(n.span()),
                        "signals.samples",
                        format!(
                            "{} samples: give a record length of at least 1",
                            n.get_ref()
                        ),
                    )
                }),
            (None, Some(base)) => Ok(base.n_samples()),
            (None, None) => Err(self.error(
                whole,
                "signals.samples",
                "give the record length, samples = N".into(),
            )),
        }
    }

    /// `[signals] sample_time`, which a built-in source fixes (1 where
    /// nothing says it).
    fn sample_time(&self, given: Option<&Spanned<f64>>, base: Option<&ModelSpec>) -> Result<f64> {
        match (given, base) {
            (Some(t), Some(base)) if t.get_ref().to_bits() != base.sample_time().to_bits() => {
                Err(self.error(
                    Some(t.span()),
                    "signals.sample_time",
                    format!(
                        "the built-in source samples every {}: leave sample_time out",
                        base.sample_time()
                    ),
                ))
            }
            (Some(t), _) if !(t.get_ref().is_finite() && *t.get_ref() > 0.0) => Err(self.error(
                Some(t.span()),
                "signals.sample_time",
                format!("{}: give a finite time > 0 between samples", t.get_ref()),
            )),
            (Some(t), _) => Ok(*t.get_ref()),
            (None, Some(base)) => Ok(base.sample_time()),
            (None, None) => Ok(1.0),
        }
    }

    pub(super) fn presets(&self, raw: &[Spanned<RawPreset>]) -> Result<Vec<(String, Preset)>> {
        let mut presets: Vec<(String, Preset)> = Vec::new();
        for p in raw {
            let r = p.get_ref();
            let name = r.name.get_ref().trim().to_string();
            if name.is_empty() || presets.iter().any(|(n, _)| *n == name) {
                return Err(self.error(
                    Some(r.name.span()),
                    "preset.name",
                    format!("'{name}' is empty or used twice: every preset needs its own name"),
                ));
            }
            let compressor: CompressorConfig =
                r.compress
                    .get_ref()
                    .parse()
                    .map_err(|e: twostage_compress::CompressError| {
                        self.error(Some(r.compress.span()), "preset.compress", e.to_string())
                    })?;
            let regressor: RegressorConfig =
                r.fit
                    .get_ref()
                    .parse()
                    .map_err(|e: twostage_fit::FitError| {
                        self.error(Some(r.fit.span()), "preset.fit", e.to_string())
                    })?;
            let simulations = match &r.sims {
                Some(m) => usize::try_from(*m.get_ref())
                    .ok()
                    .filter(|m| *m >= 2)
                    .ok_or_else(|| {
                        self.error(
                            Some(m.span()),
                            "preset.sims",
                            format!("{}: give at least 2 training simulations", m.get_ref()),
                        )
                    })?,
                None => DEFAULT_PRESET_SIMULATIONS,
            };
            presets.push((
                name,
                Preset {
                    compressor,
                    regressor,
                    simulations,
                },
            ));
        }
        Ok(presets)
    }
}

/// The most one record of a model file may take in memory, its inputs and
/// outputs as f64: every simulating thread holds at least one whole
/// record, so a record is refused before anything allocates it.
const MAX_RECORD_BYTES: usize = 1 << 30;

/// The key written just before the last `=` of `text` (quotes dropped);
/// empty without one.
fn name_before_equals(text: &str) -> String {
    let Some(equals) = text.rfind('=') else {
        return String::new();
    };
    let left = text[..equals].trim_end();
    let start = left
        .char_indices()
        .rev()
        .take_while(|(_, c)| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | '"'))
        .last()
        .map_or(left.len(), |(k, _)| k);
    left[start..].replace('"', "")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_offset_is_on_the_line_a_count_of_breaks_before_it_says() {
        let text = "a = 1\n\n[b]\nc = \"x\"\r\nd\n";
        let at = Locator::new(text, "t.toml");
        for offset in 0..=text.len() + 3 {
            let counted = 1 + text.as_bytes()[..offset.min(text.len())]
                .iter()
                .filter(|b| **b == b'\n')
                .count();
            assert_eq!(at.line(offset), counted, "offset {offset}");
        }
        assert_eq!(Locator::new("", "e.toml").line(0), 1);
    }
}
