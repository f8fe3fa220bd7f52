//! Model files: a model described in TOML, so that the command line trains
//! estimators for models other than the built-in ones. The file names the
//! parameters and their priors, the signals, the input, the measurement
//! noise, the presets, and where simulations come from. Every mistake is an
//! [`Error::ModelFile`] naming the file, the line, the key and what is
//! accepted. The annotated [`TEMPLATE`] is the reference;
//! docs/your-own-model.md walks through it.

use std::path::{Path, PathBuf};

use twostage_equations::{EquationModel, EquationSimulator, EquationsText};
use twostage_fmi::{FmiError, FmuSimulator, InterfaceKind};
use twostage_models::{
    BuiltinModel, BuiltinOverrides, ExternalSimulator, InputSignal, ModelSpec, Prior, Simulator,
};

use crate::error::{Error, Result};
use crate::preset::Preset;

/// An annotated model file, as `twostage models --template` prints it.
pub const TEMPLATE: &str = include_str!("../model_file_template.toml");

/// The simulations of a preset that does not say (and of stages given on
/// the command line for a model without presets).
pub const DEFAULT_PRESET_SIMULATIONS: usize = 2000;

/// Where a model file's simulations come from.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum ModelSource {
    /// A built-in model, with some of its settings replaced.
    Builtin {
        /// Which one.
        model: BuiltinModel,
        /// Its settings as the file changes them.
        overrides: BuiltinOverrides,
    },
    /// Another program speaking the protocol of docs/protocol.md.
    Command {
        /// The program and its arguments.
        command: Vec<String>,
        /// Where it runs: the model file's folder (or the caller's).
        dir: Option<std::path::PathBuf>,
        /// The longest wait for a record.
        timeout: std::time::Duration,
        /// Experiments per request.
        batch: usize,
        /// The protocol version it speaks (1 or 2).
        protocol: u32,
        /// The fixed input handed to it with every request (protocol 2).
        input: Option<CommandInput>,
    },
    /// An FMU (FMI 2.0 or 3.0), docs/fmu.md.
    Fmu {
        /// The FMU, relative paths resolved against the model file's folder.
        path: PathBuf,
        /// Co-simulation or model exchange (`None`: co-simulation if the
        /// FMU has it).
        interface: Option<InterfaceKind>,
        /// Communication or integration steps per sample.
        step_divisor: usize,
        /// The simulation time of the first sample.
        start_time: f64,
        /// FMU variables set before initialization in every experiment.
        starts: Vec<(String, f64)>,
        /// FMU inputs driven with white Gaussian noise: name and standard
        /// deviation, drawn in this order at every sample.
        noise_inputs: Vec<(String, f64)>,
        /// The design of the measured inputs.
        input: Option<InputSignal>,
    },
    /// The model written as equations in the file (`[equations]`),
    /// simulated natively.
    Equations {
        /// The equations as written.
        text: EquationsText,
        /// Multiplicative log-normal output noise: output, sd, line.
        lognormal: Vec<(String, f64, usize)>,
        /// The line of `[equations]`.
        line: usize,
        /// The design of the inputs.
        input: Option<InputSignal>,
    },
    /// None: the file describes charts simulated elsewhere.
    ChartsOnly,
}

/// The input a model file hands a command source (protocol 2): fixed for
/// every experiment, or a design drawn per experiment.
#[derive(Debug, Clone, PartialEq)]
pub enum CommandInput {
    /// A design (a multisine, a random binary sequence, ...) that twostage
    /// draws from each experiment's stream and hands to the simulator with
    /// the experiment (`each`, docs/protocol.md).
    Drawn(InputSignal),
    /// The same values for every input signal.
    Values(InputSignal),
    /// A CSV file (a measured record, say) whose columns named as the
    /// model's inputs are read; other columns are ignored.
    File {
        /// The file, relative paths resolved against the model file's folder.
        path: PathBuf,
        /// The line of `file = ...` in the model file.
        line: usize,
        /// The columns to read, in the order of the model's inputs (`None`:
        /// the columns named as the inputs).
        columns: Option<Vec<String>>,
        /// The data rows to read, first and last from 1, inclusive (`None`:
        /// all of them).
        rows: Option<[usize; 2]>,
    },
}

/// How `models` describes an input the file fixes.
fn fixed_input_note(fixed: &CommandInput, inputs: &[&str]) -> String {
    match fixed {
        CommandInput::Drawn(signal) => {
            format!(
                "drawn by twostage per experiment and handed to the simulator: {}",
                signal.describe()
            )
        }
        CommandInput::Values(signal) => {
            format!("fixed for every experiment: {}", signal.describe())
        }
        CommandInput::File {
            path,
            columns,
            rows,
            ..
        } => {
            let names = columns
                .as_ref()
                .map_or_else(|| inputs.join(", "), |c| c.join(", "));
            format!(
                "fixed for every experiment: the {names} column{} of {}{}",
                if inputs.len() == 1 { "" } else { "s" },
                path.display(),
                rows.map_or_else(String::new, |[a, b]| format!(", rows {a} to {b}"))
            )
        }
    }
}

/// A model described by a model file.
///
/// ```
/// use twostage_sources::ModelFile;
/// let file = ModelFile::parse(
///     r#"
///     [model]
///     name = "short-benchmark"
///     [source]
///     builtin = "benchmark"
///     [[parameter]]
///     name = "theta"
///     prior = { dist = "truncnormal", mu = 0.0, sigma = 0.3, low = -0.9, high = 0.9 }
///     [signals]
///     samples = 300
///     [[preset]]
///     name = "small"
///     compress = "arx:3,3"
///     fit = "mlp:6"
///     sims = 800
///     "#,
///     "short.toml",
/// )?;
/// let simulator = file.simulator()?;
/// assert_eq!(simulator.spec().n_samples(), 300);
/// assert_eq!(file.preset("small")?.simulations, 800);
/// # Ok::<(), twostage_sources::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct ModelFile {
    origin: String,
    description: String,
    source: ModelSource,
    spec: ModelSpec,
    output_sd: Vec<f64>,
    /// Per output, the AR(1) coefficient of that noise (0: white).
    output_ar: Vec<f64>,
    /// A measured residual whose spectrum the output noise takes
    /// (`[noise] output_residual`), with the line that names it.
    output_residual: Option<(PathBuf, usize)>,
    presets: Vec<(String, Preset)>,
    /// Where each name the source must know was written: (name, key, line).
    name_lines: Vec<(String, &'static str, usize)>,
    /// The line of `fmu = ...`.
    fmu_line: Option<usize>,
    /// A measured input from a file, for a built-in or FMU source (a
    /// command's is in its [`ModelSource::Command`]).
    measured_input: Option<CommandInput>,
    /// The equations compiled, for an equations source.
    equations: Option<EquationModel>,
    /// Identifies the file's text (shards record it).
    fingerprint: u64,
}

/// The largest model file read: it is read and parsed whole, the parser
/// holding many times its size, and a model that needs more words than
/// this is better a compiled simulator (docs/reliability.md).
const MAX_MODEL_FILE_BYTES: u64 = 16 << 20;

impl ModelFile {
    /// Read and check a model file.
    ///
    /// # Errors
    /// [`Error::Io`] if it cannot be read, [`Error::ModelFile`] for every
    /// mistake in it.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let io = |cause| Error::Io {
            path: path.display().to_string(),
            cause,
        };
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > MAX_MODEL_FILE_BYTES {
            return Err(io(std::io::Error::other(format!(
                "a file of {}, where a model file takes at most {}: not a model file, or \
                 equations that belong in a compiled simulator",
                crate::readable_bytes(size as f64),
                crate::readable_bytes(MAX_MODEL_FILE_BYTES as f64)
            ))));
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        // A command runs beside its model file, so that `python3 sim.py` works
        // from any folder; an FMU is found beside it.
        let folder = path.parent().map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        });
        let mut file = Self::parse_beside(&text, &path.display().to_string(), folder)?;
        match &mut file.source {
            ModelSource::Command { dir, .. } => *dir = folder.map(Path::to_path_buf),
            ModelSource::Fmu { path: fmu, .. } => {
                if let Some(folder) = folder.filter(|_| fmu.is_relative()) {
                    *fmu = folder.join(&*fmu);
                }
            }
            _ => {}
        }
        // A measured residual's file, likewise.
        if let (Some((residual, _)), Some(folder)) = (&mut file.output_residual, folder)
            && residual.is_relative()
        {
            *residual = folder.join(&*residual);
        }
        // A measured input's file is found beside the model file too.
        if let (Some(CommandInput::File { path: input, .. }), Some(folder)) =
            (&mut file.measured_input, folder)
            && input.is_relative()
        {
            *input = folder.join(&*input);
        }
        Ok(file)
    }

    /// Check the text of a model file; `origin` names it in messages.
    ///
    /// # Errors
    /// [`Error::ModelFile`] naming the line, the key and what is accepted.
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        Self::parse_beside(text, origin, None)
    }

    /// [`ModelFile::parse`], the files it names (a `like` record) read
    /// from `folder` where relative.
    fn parse_beside(text: &str, origin: &str, folder: Option<&Path>) -> Result<Self> {
        let at = Locator::new(text, origin).beside(folder);
        let raw: RawFile = toml::from_str(text).map_err(|e| Error::ModelFile {
            file: origin.to_string(),
            line: e.span().map(|s| at.line(s.start)),
            key: e.span().map(|s| at.key_at(s.start)).unwrap_or_default(),
            message: e.message().to_string(),
        })?;
        let mut source = match &raw.equations {
            Some(equations) => at.equations(
                equations,
                raw.source.as_ref(),
                raw.noise.as_ref(),
                raw.input.as_ref(),
            )?,
            None => at.source(raw.source.as_ref(), raw.noise.as_ref(), raw.input.as_ref())?,
        };
        let measured_input = match source {
            ModelSource::Builtin { .. }
            | ModelSource::Fmu { .. }
            | ModelSource::Equations { .. } => at.measured_input(raw.input.as_ref())?,
            _ => None,
        };
        let builtin = match &source {
            ModelSource::Builtin { model, overrides } => {
                Some((*model, model.build_with(overrides)?))
            }
            ModelSource::Command { .. }
            | ModelSource::Fmu { .. }
            | ModelSource::Equations { .. }
            | ModelSource::ChartsOnly => None,
        };
        let base = builtin.as_ref().map(|(_, sim)| sim.spec());
        let (names, marginals) = at.parameters(&raw.parameter, base)?;
        let signals = at.signals(raw.signals.as_ref(), base)?;
        if let ModelSource::Builtin { overrides, .. } = &mut source
            && base.is_some_and(|b| b.n_samples() != signals.samples)
        {
            overrides.n_samples = Some(signals.samples);
        }
        let prior =
            Prior::new(marginals).map_err(|e| at.error(None, "parameter", e.to_string()))?;
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        let inputs: Vec<&str> = signals.inputs.iter().map(String::as_str).collect();
        let outputs: Vec<&str> = signals.outputs.iter().map(String::as_str).collect();
        let spec = ModelSpec::new(
            raw.model.name.get_ref(),
            &names,
            prior,
            signals.sample_time,
            signals.samples,
        )
        .map_err(|e| at.error(Some(raw.model.name.span()), "model", e.to_string()))?
        .with_signals(&inputs, &outputs);
        // A built-in source's parameters, given no [[parameter]], are the
        // plant's.
        let mut per_record: Vec<bool> = raw
            .parameter
            .iter()
            .map(|p| p.get_ref().per_record)
            .collect();
        per_record.resize(names.len(), false);
        let spec = spec
            .with_per_record(&per_record)
            .map_err(|e| at.error(None, "parameter.per_record", e.to_string()))?;
        let spec = match base {
            // The car's equations stay the file's while its parameters
            // are the car's own (a linearized stage 1 reads them).
            Some(b) => match b.car_equations() {
                Some(equations) if spec.param_names() == b.param_names() => spec
                    .with_notes(b.input_note(), b.noise_note())
                    .with_car_equations(*equations),
                _ => spec.with_notes(b.input_note(), b.noise_note()),
            },
            None => spec,
        };
        at.check_inputs(&raw, &source, &signals, measured_input.is_some())?;
        let spec = match &source {
            ModelSource::Fmu {
                input,
                noise_inputs,
                ..
            } => spec.with_notes(
                &input
                    .as_ref()
                    .map(InputSignal::describe)
                    .unwrap_or_default(),
                &noise_inputs
                    .iter()
                    .map(|(name, sd)| format!("{name} ~ N(0, {sd}^2)"))
                    .collect::<Vec<_>>()
                    .join(", "),
            ),
            ModelSource::Equations {
                text,
                lognormal,
                input,
                ..
            } => spec.with_notes(
                &input
                    .as_ref()
                    .map(InputSignal::describe)
                    .unwrap_or_default(),
                &equations::noise_note(text, lognormal),
            ),
            _ => spec,
        };
        let compiled = match &source {
            ModelSource::Equations {
                text,
                lognormal,
                line,
                ..
            } => Some(equations::compile(origin, (text, lognormal, *line), &spec)?),
            _ => None,
        };
        let output_sd = at.output_noise(raw.noise.as_ref(), outputs.len())?;
        let output_ar = at.output_correlation(raw.noise.as_ref(), outputs.len(), &output_sd)?;
        let output_residual = at.output_residual(raw.noise.as_ref(), &output_sd)?;
        // What `models` says of the input and noise: a fixed input is the
        // one thing a user must know before estimating a record of another.
        let fixed = match (&source, &measured_input) {
            (ModelSource::Command { input, .. }, _) => input.as_ref(),
            (_, measured) => measured.as_ref(),
        };
        let input_note = match (fixed, &source) {
            (Some(fixed), _) => fixed_input_note(fixed, &inputs),
            (None, ModelSource::Command { .. }) if !inputs.is_empty() => {
                "the simulator's own, drawn per experiment".to_string()
            }
            (None, _) => spec.input_note().to_string(),
        };
        let own_noise = match &source {
            ModelSource::Command { .. } => "the simulator's own".to_string(),
            _ => spec.noise_note().to_string(),
        };
        let noise_note = noise::added_noise_note(
            own_noise,
            &outputs,
            (&output_sd, &output_ar),
            output_residual.as_ref().map(|(path, _)| path.as_path()),
        );
        let spec = spec.with_notes(&input_note, &noise_note);
        let presets = at.presets(&raw.preset)?;
        let name_lines = at.name_lines(&raw);
        let fmu_line = raw
            .source
            .as_ref()
            .and_then(|s| s.get_ref().fmu.as_ref())
            .map(|f| at.line(f.span().start));
        Ok(Self {
            origin: origin.to_string(),
            description: raw.model.description.unwrap_or_default(),
            source,
            spec,
            output_sd,
            output_ar,
            output_residual,
            presets,
            name_lines,
            fmu_line,
            measured_input,
            equations: compiled,
            fingerprint: crate::fingerprint(text.as_bytes()),
        })
    }

    /// The model's name, parameters, prior, sampling and signals.
    pub fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        self.spec.name()
    }

    /// A hash of the file's text ([`crate::fingerprint`]): shards simulated
    /// from it record it, and training checks it.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// What the file says the model is, for people.
    pub fn description(&self) -> &str {
        &self.description
    }

    /// Where simulations come from.
    pub fn source(&self) -> &ModelSource {
        &self.source
    }

    /// The file as it was named when read (its path, or what the caller
    /// called its text).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The simulator the file describes.
    ///
    /// # Errors
    /// [`Error::ModelFile`] for a file without a source (it describes
    /// charts simulated elsewhere).
    pub fn simulator(&self) -> Result<Box<dyn Simulator>> {
        match &self.source {
            ModelSource::Builtin { model, overrides } => Ok(Box::new(FileSimulator {
                inner: model.build_with(overrides)?,
                spec: self.spec.clone(),
                output_noise: self.output_noise()?,
                fixed_input: self.measured_record()?,
                design: None,
            })),
            ModelSource::Command {
                command,
                dir,
                timeout,
                batch,
                protocol,
                input,
            } => {
                let mut external = ExternalSimulator::new(self.spec.clone(), command.clone())?
                    .timeout(*timeout)
                    .batch(*batch)
                    .protocol(*protocol)?;
                if let Some(dir) = dir {
                    external = external.current_dir(dir);
                }
                let (fixed_input, design) = match input {
                    Some(CommandInput::Drawn(design)) => (None, Some(design.clone())),
                    Some(fixed) => (Some(self.fixed_record(fixed, dir.as_deref())?), None),
                    None => (None, None),
                };
                Ok(Box::new(FileSimulator {
                    inner: Box::new(external),
                    spec: self.spec.clone(),
                    output_noise: self.output_noise()?,
                    fixed_input,
                    design,
                }))
            }
            ModelSource::Fmu {
                path,
                interface,
                step_divisor,
                start_time,
                starts,
                noise_inputs,
                input,
            } => {
                let mut builder = FmuSimulator::builder(path, self.spec.clone())
                    .step_divisor(*step_divisor)
                    .start_time(*start_time);
                if let Some(kind) = interface {
                    builder = builder.interface(*kind);
                }
                if let Some(input) = input {
                    builder = builder.input(input.clone());
                }
                for (name, sd) in noise_inputs {
                    builder = builder.noise_input(name, *sd);
                }
                for (name, value) in starts {
                    builder = builder.start(name, *value);
                }
                let fmu = builder.build().map_err(|e| self.fmu_error(e))?;
                Ok(Box::new(FileSimulator {
                    inner: Box::new(fmu),
                    spec: self.spec.clone(),
                    output_noise: self.output_noise()?,
                    fixed_input: self.measured_record()?,
                    design: None,
                }))
            }
            ModelSource::Equations { input, .. } => {
                let model = self.equations.clone().ok_or_else(|| Error::ModelFile {
                    file: self.origin.clone(),
                    line: None,
                    key: "equations".into(),
                    message: "the equations were not compiled at load".into(),
                })?;
                Ok(Box::new(FileSimulator {
                    inner: Box::new(EquationSimulator::new(
                        self.spec.clone(),
                        model,
                        input.clone(),
                    )),
                    spec: self.spec.clone(),
                    output_noise: self.output_noise()?,
                    fixed_input: self.measured_record()?,
                    design: None,
                }))
            }
            ModelSource::ChartsOnly => Err(Error::ModelFile {
                file: self.origin.clone(),
                line: None,
                key: "source".into(),
                message: "the file has no [source], so nothing can be simulated: add one \
                          (a file without it describes charts simulated elsewhere, which this \
                          command cannot use)"
                    .into(),
            }),
        }
    }

    /// The file's model simulated by `source`, a simulator the caller
    /// supplies (a Python function, say): the file gives the names, prior,
    /// signals and measurement noise, `source` the records. Only a file
    /// without a `[source]` of its own takes one.
    ///
    /// # Errors
    /// [`Error::ModelFile`] when the file names its own source, or when
    /// `source` simulates records of another shape than the file's.
    pub fn simulator_with(&self, source: Box<dyn Simulator>) -> Result<Box<dyn Simulator>> {
        let error = |key: &str, message: String| Error::ModelFile {
            file: self.origin.clone(),
            line: None,
            key: key.into(),
            message,
        };
        if !matches!(self.source, ModelSource::ChartsOnly) {
            return Err(error(
                "source",
                "the file names its own [source]: leave it out to simulate with the one given \
                 here"
                    .into(),
            ));
        }
        let (mine, theirs) = (&self.spec, source.spec());
        if mine.n_params() != theirs.n_params()
            || mine.input_names().len() != theirs.input_names().len()
            || mine.output_names().len() != theirs.output_names().len()
            || mine.n_samples() != theirs.n_samples()
        {
            return Err(error(
                "signals",
                format!(
                    "the given simulator has {} parameters, {} inputs, {} outputs and {} \
                     samples; the file says {}, {}, {} and {}",
                    theirs.n_params(),
                    theirs.input_names().len(),
                    theirs.output_names().len(),
                    theirs.n_samples(),
                    mine.n_params(),
                    mine.input_names().len(),
                    mine.output_names().len(),
                    mine.n_samples()
                ),
            ));
        }
        Ok(Box::new(FileSimulator {
            inner: source,
            spec: self.spec.clone(),
            output_noise: self.output_noise()?,
            fixed_input: None,
            design: None,
        }))
    }

    /// Each output's noise: shaped like the measured residual (an AR model
    /// of it, order by BIC), else `output_sd` with its `output_ar`.
    fn output_noise(&self) -> Result<Vec<twostage_models::ArNoise>> {
        let Some((path, line)) = &self.output_residual else {
            return Ok(self
                .output_sd
                .iter()
                .zip(&self.output_ar)
                .map(|(sd, a)| twostage_models::ArNoise::ar1(*a, *sd))
                .collect());
        };
        let error = |message: String| Error::ModelFile {
            file: self.origin.clone(),
            line: Some(*line),
            key: "noise.output_residual".into(),
            message,
        };
        let columns = crate::csv_rows::read_columns(path, self.spec.output_names())
            .map_err(|problem| error(problem.to_string()))?;
        columns
            .iter()
            .zip(self.spec.output_names())
            .map(|(column, name)| {
                if column.len() < 50 {
                    return Err(error(format!(
                        "{} holds {} samples of {name}: a residual's spectrum needs at least 50",
                        path.display(),
                        column.len()
                    )));
                }
                let mean = column.iter().sum::<f64>() / column.len() as f64;
                let centred: Vec<f64> = column.iter().map(|v| v - mean).collect();
                Ok(twostage_models::ArNoise::fit(&centred, 20, 0))
            })
            .collect()
    }

    /// An FMU's complaint, placed at the line of the name it concerns (or
    /// of `fmu = ...`).
    fn fmu_error(&self, e: FmiError) -> Error {
        let (key, line) = match &e {
            FmiError::Variable { name, .. } => self
                .name_lines
                .iter()
                .rfind(|(n, _, _)| n == name)
                .map_or(("source.fmu", self.fmu_line), |(_, key, line)| {
                    (*key, Some(*line))
                }),
            _ => ("source.fmu", self.fmu_line),
        };
        Error::ModelFile {
            file: self.origin.clone(),
            line,
            key: key.into(),
            message: e.to_string(),
        }
    }

    /// The model as charts read from files need it: its spec, without
    /// simulating (a file without a source has nothing to simulate with;
    /// one with a source simulates as [`ModelFile::simulator`] does).
    pub fn chart_model(&self) -> Result<Box<dyn Simulator>> {
        match self.source {
            ModelSource::ChartsOnly => Ok(Box::new(ChartsOnly {
                spec: self.spec.clone(),
                origin: self.origin.clone(),
            })),
            _ => self.simulator(),
        }
    }

    /// The file's presets, in its order (a built-in source's own come on
    /// top through the facade's named model).
    pub fn preset_names(&self) -> impl Iterator<Item = &str> {
        self.presets.iter().map(|(name, _)| name.as_str())
    }

    /// A preset by name.
    ///
    /// # Errors
    /// [`Error::NotAvailable`] naming the presets that exist.
    pub fn preset(&self, name: &str) -> Result<Preset> {
        self.presets
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p.clone())
            .ok_or_else(|| Error::NotAvailable {
                what: "preset",
                name: name.to_string(),
                model: self.name().to_string(),
                available: if self.presets.is_empty() {
                    "none (add a [[preset]], or give the stages on the command line)".into()
                } else {
                    self.preset_names().collect::<Vec<_>>().join(", ")
                },
            })
    }
}

mod equations;
mod fmu_template;
mod input;
mod locator;
mod noise;
mod priors;
mod raw;
mod shape;
mod simulator;

pub use fmu_template::fmu_model_file;
use locator::Locator;
use raw::RawFile;
use simulator::{ChartsOnly, FileSimulator};

#[cfg(test)]
mod tests;
