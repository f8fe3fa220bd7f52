//! A model file's `[input]`: the source's own design, or a fixed input
//! (values, or a measured record's columns) the model file hands over.

use std::path::{Path, PathBuf};

use toml::Spanned;
use twostage_models::{Drawn, Grid, InputSignal, Level, Phases, Taper};

use super::locator::Locator;
use super::locator::Signals;
use super::raw::RawFile;
use super::raw::{OneOrMany, RawInput};
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
        // A design's frequencies against the records' sample time.
        let designed = match source {
            ModelSource::Builtin { overrides, .. } => overrides.input.as_ref(),
            ModelSource::Fmu { input, .. } | ModelSource::Equations { input, .. } => input.as_ref(),
            ModelSource::Command {
                input: Some(CommandInput::Drawn(design)),
                ..
            } => Some(design),
            _ => None,
        };
        if let Some(signal) = designed {
            signal
                .check_sampling(signals.sample_time, signals.samples)
                .map_err(|e| {
                    self.error(
                        raw.input.as_ref().map(Spanned::span),
                        "input",
                        e.to_string(),
                    )
                })?;
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

    /// A command's input: a design drawn per experiment, or a fixed one
    /// (`values` for every input signal, or a CSV `file` whose columns are
    /// named as the model's inputs).
    pub(super) fn command_input(&self, input: &Spanned<RawInput>) -> Result<CommandInput> {
        let raw = input.get_ref();
        let fixed_only = || {
            self.error(
                Some(raw.signal.span()),
                "input.signal",
                "a fixed input takes values or file = \"record.csv\" (a measured input)".into(),
            )
        };
        if raw.signal.get_ref() != "fixed" {
            return self.input(input).map(CommandInput::Drawn);
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
        let (takes, needs): (&[&str], &[&str]) = match kind {
            "white" => (&["sd"], &["sd"]),
            "chicane" => (&["amplitude"], &["amplitude"]),
            "fixed" => (&["values"], &["values"]),
            "multisine" => (
                &[
                    "band", "grid", "phases", "rms", "peak", "offset", "spectrum", "like",
                ],
                &["band"],
            ),
            "binary" => (&["amplitude", "hold", "offset"], &["amplitude", "hold"]),
            "prbs" => (
                &["order", "amplitude", "hold", "offset"],
                &["order", "amplitude", "hold"],
            ),
            "sweep" => (&["band", "amplitude", "offset"], &["band", "amplitude"]),
            "gaussian" => (
                &["band", "order", "rms", "offset", "spectrum", "like"],
                &["band", "rms"],
            ),
            "steps" => (&["levels", "hold_seconds"], &["levels", "hold_seconds"]),
            "bursts" => (
                &[
                    "count",
                    "seconds",
                    "cycles",
                    "amplitude",
                    "taper",
                    "dwell",
                    "offset",
                ],
                &["seconds", "cycles", "amplitude"],
            ),
            "ramps" => (
                &["levels", "hold_seconds", "ramp_seconds", "offset"],
                &["levels", "hold_seconds"],
            ),
            "sum" | "sequence" => (&["parts"], &["parts"]),
            "mix" => (&["parts", "weights"], &["parts"]),
            other => {
                return Err(self.error(
                    Some(raw.signal.span()),
                    "input.signal",
                    format!(
                        "unknown signal '{other}': use \"white\", \"chicane\", \"fixed\", \
                         \"multisine\", \"binary\", \"prbs\", \"gaussian\", \"sweep\", \"steps\", \
                         \"ramps\", \"bursts\", \"sum\", \"mix\" or \"sequence\""
                    ),
                ));
            }
        };
        let given = [
            ("sd", raw.sd.is_some()),
            ("amplitude", raw.amplitude.is_some()),
            ("values", raw.values.is_some()),
            ("band", raw.band.is_some()),
            ("grid", raw.grid.is_some()),
            ("phases", raw.phases.is_some()),
            ("rms", raw.rms.is_some()),
            ("peak", raw.peak.is_some()),
            ("offset", raw.offset.is_some()),
            ("hold", raw.hold.is_some()),
            ("order", raw.order.is_some()),
            ("levels", raw.levels.is_some()),
            ("hold_seconds", raw.hold_seconds.is_some()),
            ("count", raw.count.is_some()),
            ("seconds", raw.seconds.is_some()),
            ("cycles", raw.cycles.is_some()),
            ("taper", raw.taper.is_some()),
            ("dwell", raw.dwell.is_some()),
            ("parts", raw.parts.is_some()),
            ("ramp_seconds", raw.ramp_seconds.is_some()),
            ("weights", raw.weights.is_some()),
            ("spectrum", raw.spectrum.is_some()),
            ("like", raw.like.is_some()),
        ];
        if let Some((key, _)) = given.iter().find(|(k, g)| *g && !takes.contains(k)) {
            return Err(self.error(
                here(),
                &format!("input.{key}"),
                format!("a \"{kind}\" input takes {} only", takes.join(", ")),
            ));
        }
        if let Some(key) = needs
            .iter()
            .find(|k| !given.iter().any(|(g, is)| g == *k && *is))
        {
            return Err(self.error(
                here(),
                &format!("input.{key}"),
                format!("a \"{kind}\" input needs {}", needs.join(", ")),
            ));
        }
        let wrong =
            |key: &str, message: String| self.error(here(), &format!("input.{key}"), message);
        let drawn = |key: &str, value: &OneOrMany| -> Result<Drawn> {
            match value {
                OneOrMany::One(v) => Ok(Drawn::fixed(*v)),
                OneOrMany::Many(ends) if ends.len() == 2 => {
                    Drawn::between(ends[0], ends[1]).map_err(|e| wrong(key, e.to_string()))
                }
                OneOrMany::Many(ends) => Err(wrong(
                    key,
                    format!(
                        "{} values: give one value, or [low, high] to draw one per experiment",
                        ends.len()
                    ),
                )),
            }
        };
        let amplitude = raw
            .amplitude
            .as_ref()
            .map(|a| drawn("amplitude", a))
            .transpose()?;
        // A drawn offset is set on the design after it is built.
        let (offset, drawn_offset) = match &raw.offset {
            None => (0.0, None),
            Some(OneOrMany::One(v)) => (*v, None),
            Some(range) => (0.0, Some(drawn("offset", range)?)),
        };
        let signal = match kind {
            "white" => raw.sd.map(InputSignal::white_gaussian),
            "chicane" => match &raw.amplitude {
                Some(OneOrMany::One(a)) => Some(InputSignal::chicane(*a)),
                _ => {
                    return Err(wrong(
                        "amplitude",
                        "a chicane takes one amplitude, the same in every experiment".into(),
                    ));
                }
            },
            "fixed" => raw.values.clone().map(InputSignal::fixed),
            "multisine" => {
                let (low, top) = raw
                    .band
                    .as_ref()
                    .map(|(l, t)| (l, t))
                    .unwrap_or_else(|| unreachable!("needed"));
                let grid = match raw.grid.as_deref() {
                    None | Some("full") => Grid::Full,
                    Some("odd") => Grid::Odd,
                    Some(other) => {
                        return Err(wrong("grid", format!("'{other}': use \"full\" or \"odd\"")));
                    }
                };
                let phases = match raw.phases.as_deref() {
                    None | Some("random") => Phases::Random,
                    Some("schroeder") => Phases::Schroeder,
                    Some(other) => {
                        return Err(wrong(
                            "phases",
                            format!("'{other}': use \"random\" or \"schroeder\""),
                        ));
                    }
                };
                let level = match (&raw.rms, &raw.peak) {
                    (Some(r), None) => Level::Rms(drawn("rms", r)?),
                    (None, Some(p)) => Level::Peak(drawn("peak", p)?),
                    (None, None) => Level::Rms(Drawn::fixed(1.0)),
                    (Some(_), Some(_)) => {
                        return Err(wrong("peak", "give rms or peak, not both".into()));
                    }
                };
                Some(InputSignal::multisine(
                    drawn("band", low)?,
                    drawn("band", top)?,
                    grid,
                    phases,
                    level,
                    offset,
                ))
            }
            "binary" => amplitude
                .zip(raw.hold)
                .map(|(a, hold)| InputSignal::random_binary(a, hold, offset)),
            "prbs" => match (raw.order, amplitude, raw.hold) {
                (Some(order), Some(a), Some(hold)) => {
                    Some(InputSignal::prbs(order, a, hold, offset))
                }
                _ => None,
            },
            "sweep" => match (&raw.band, amplitude) {
                (Some((from, to)), Some(a)) => Some(InputSignal::sweep(
                    drawn("band", from)?,
                    drawn("band", to)?,
                    a,
                    offset,
                )),
                _ => None,
            },
            "gaussian" => match (&raw.band, &raw.rms) {
                (Some((low, top)), Some(rms)) => Some(InputSignal::filtered_noise(
                    drawn("band", low)?,
                    drawn("band", top)?,
                    raw.order.unwrap_or(DEFAULT_FILTER_ORDER),
                    drawn("rms", rms)?,
                    offset,
                )),
                _ => None,
            },
            "sum" => {
                let parts = raw.parts.as_deref().unwrap_or_default();
                // A part is one design: a sum of sums is refused, so the
                // parts' depth stays one whatever the file says.
                if let Some(inner) = parts
                    .iter()
                    .find(|p| p.get_ref().parts.is_some() || p.get_ref().signal.get_ref() == "sum")
                {
                    return Err(self.error(
                        Some(inner.span()),
                        "input.parts",
                        "a part of a sum is one design: give the inner sum's parts to the \
                         outer sum"
                            .into(),
                    ));
                }
                let parts = parts
                    .iter()
                    .map(|p| self.input(p))
                    .collect::<Result<Vec<_>>>()?;
                Some(InputSignal::sum(parts))
            }
            "mix" | "sequence" => {
                let parts = raw.parts.as_deref().unwrap_or_default();
                if parts.is_empty() {
                    return Err(wrong(
                        "parts",
                        format!("a \"{kind}\" input needs one or more parts to draw from"),
                    ));
                }
                let parts = parts
                    .iter()
                    .map(|p| self.input(p))
                    .collect::<Result<Vec<_>>>()?;
                if kind == "sequence" {
                    Some(InputSignal::sequence(parts))
                } else {
                    let weights = raw
                        .weights
                        .clone()
                        .unwrap_or_else(|| vec![1.0; parts.len()]);
                    if weights.len() != parts.len() {
                        return Err(wrong(
                            "weights",
                            format!(
                                "{} weight(s) for {} part(s): give one per part, or none for \
                                 equal chances",
                                weights.len(),
                                parts.len()
                            ),
                        ));
                    }
                    Some(InputSignal::one_of(parts, weights))
                }
            }
            "ramps" => match (raw.levels, raw.hold_seconds) {
                (Some([low, high]), Some([shortest, longest])) => {
                    let level =
                        Drawn::between(low, high).map_err(|e| wrong("levels", e.to_string()))?;
                    let hold = Drawn::between(shortest, longest)
                        .map_err(|e| wrong("hold_seconds", e.to_string()))?;
                    let ramp = match &raw.ramp_seconds {
                        None => Drawn::fixed(0.0),
                        Some(r) => drawn("ramp_seconds", r)?,
                    };
                    Some(InputSignal::ramps(level, hold, ramp, offset))
                }
                _ => None,
            },
            "bursts" => {
                let count = match &raw.count {
                    None => (1, 1),
                    Some(count) => {
                        let (low, high) = drawn("count", count)?.range();
                        let whole =
                            |v: f64| v.fract().abs() < f64::EPSILON && (0.0..=1e9).contains(&v);
                        if !(whole(low) && whole(high)) {
                            return Err(wrong(
                                "count",
                                format!("[{low}, {high}]: give whole numbers of bursts per record"),
                            ));
                        }
                        (low as usize, high as usize)
                    }
                };
                let taper = match raw.taper.as_deref() {
                    None | Some("hann") => Taper::Hann,
                    Some("none") => Taper::None,
                    Some("mixed") => Taper::Mixed,
                    Some(other) => {
                        return Err(wrong(
                            "taper",
                            format!("'{other}': use \"hann\", \"none\" or \"mixed\""),
                        ));
                    }
                };
                match (&raw.seconds, &raw.cycles, amplitude) {
                    (Some(seconds), Some(cycles), Some(a)) => Some(InputSignal::bursts(
                        count,
                        drawn("seconds", seconds)?,
                        drawn("cycles", cycles)?,
                        a,
                        taper,
                        match &raw.dwell {
                            None => Drawn::fixed(0.0),
                            Some(dwell) => drawn("dwell", dwell)?,
                        },
                        offset,
                    )),
                    _ => None,
                }
            }
            "steps" => raw
                .levels
                .zip(raw.hold_seconds)
                .map(|(l, h)| InputSignal::steps((l[0], l[1]), (h[0], h[1]))),
            _ => unreachable!("the kinds are matched above"),
        };
        let shape = self.spectrum(raw)?;
        if let (Some(_), Some(_)) = (&shape, raw.order) {
            return Err(wrong(
                "order",
                "a shaped noise is drawn line by line on the record's grid: order sets the \
                 filters of an unshaped one; give spectrum or like, or order"
                    .into(),
            ));
        }
        signal
            .unwrap_or_else(|| unreachable!("every needed key is given"))
            .and_then(|s| match shape {
                Some(shape) => s.with_spectrum(shape),
                None => Ok(s),
            })
            .and_then(|s| match drawn_offset {
                Some(offset) => s.with_offset(offset),
                None => Ok(s),
            })
            .map_err(|e| self.error(here(), "input", e.to_string()))
    }
}

/// The Butterworth order of a `gaussian` input whose file gives none: a
/// 24 dB-per-octave edge, sharp enough to keep the band without a long
/// start-up.
const DEFAULT_FILTER_ORDER: u32 = 4;

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
            CommandInput::Drawn(design) => {
                return design
                    .shared_record(&self.spec)
                    .ok_or_else(|| Error::ModelFile {
                        file: self.origin.clone(),
                        line: None,
                        key: "input.signal".into(),
                        message: format!(
                            "{} is drawn anew per experiment: it is no one record",
                            design.describe()
                        ),
                    });
            }
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
                    .map_err(|problem| error("input.file", problem.to_string()))?;
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
