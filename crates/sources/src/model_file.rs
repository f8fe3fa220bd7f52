//! Model files: a model described in TOML, so that the command line trains
//! estimators for models other than the built-in ones. The file names the
//! parameters and their priors, the signals, the input, the measurement
//! noise, the presets, and where simulations come from. Every mistake is an
//! [`Error::ModelFile`] naming the file, the line, the key and what is
//! accepted. The annotated [`TEMPLATE`] is the reference;
//! docs/your-own-model.md walks through it.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;
use twostage_fmi::{FmiError, FmuSimulator, InterfaceKind};
use twostage_models::{
    BuiltinModel, BuiltinOverrides, ExperimentRng, ExternalSimulator, InputSignal, IoData,
    Marginal, ModelSpec, Prior, Simulator,
};

use crate::error::{Error, Result};
use crate::preset::Preset;
use twostage_compress::CompressorConfig;
use twostage_fit::RegressorConfig;

/// An annotated model file, as `twostage models --template` prints it.
pub const TEMPLATE: &str = include_str!("model_file_template.toml");

/// The simulations of a preset that does not say.
const DEFAULT_PRESET_SIMULATIONS: usize = 2000;

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
    /// None: the file describes charts simulated elsewhere.
    ChartsOnly,
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
    presets: Vec<(String, Preset)>,
    /// Where each name the source must know was written: (name, key, line).
    name_lines: Vec<(String, &'static str, usize)>,
    /// The line of `fmu = ...`.
    fmu_line: Option<usize>,
    /// Identifies the file's text (shards record it).
    fingerprint: u64,
}

impl ModelFile {
    /// Read and check a model file.
    ///
    /// # Errors
    /// [`Error::Io`] if it cannot be read, [`Error::ModelFile`] for every
    /// mistake in it.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|cause| Error::Io {
            path: path.display().to_string(),
            cause,
        })?;
        let mut file = Self::parse(&text, &path.display().to_string())?;
        // A command runs beside its model file, so that `python3 sim.py` works
        // from any folder; an FMU is found beside it.
        let folder = path.parent().map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        });
        match &mut file.source {
            ModelSource::Command { dir, .. } => *dir = folder.map(Path::to_path_buf),
            ModelSource::Fmu { path: fmu, .. } => {
                if let Some(folder) = folder.filter(|_| fmu.is_relative()) {
                    *fmu = folder.join(&*fmu);
                }
            }
            _ => {}
        }
        Ok(file)
    }

    /// Check the text of a model file; `origin` names it in messages.
    ///
    /// # Errors
    /// [`Error::ModelFile`] naming the line, the key and what is accepted.
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        let at = Locator { text, origin };
        let raw: RawFile = toml::from_str(text).map_err(|e| Error::ModelFile {
            file: origin.to_string(),
            line: e.span().map(|s| at.line(s.start)),
            key: String::new(),
            message: e.message().to_string(),
        })?;
        let mut source = at.source(raw.source.as_ref(), raw.noise.as_ref(), raw.input.as_ref())?;
        let builtin = match &source {
            ModelSource::Builtin { model, overrides } => {
                Some((*model, model.build_with(overrides)?))
            }
            ModelSource::Command { .. } | ModelSource::Fmu { .. } | ModelSource::ChartsOnly => None,
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
        let spec = match base {
            Some(b) => spec.with_notes(b.input_note(), b.noise_note()),
            None => spec,
        };
        if let (ModelSource::Fmu { .. }, None) = (
            &source,
            raw.signals
                .as_ref()
                .and_then(|s| s.get_ref().sample_time.as_ref()),
        ) {
            return Err(at.error(
                raw.signals.as_ref().map(Spanned::span),
                "signals.sample_time",
                "an FMU runs in its own time unit: give the time between samples, \
                 sample_time = T"
                    .into(),
            ));
        }
        if let ModelSource::Fmu { input, .. } = &source {
            let span = raw.signals.as_ref().map(Spanned::span);
            if input.is_none() && !signals.inputs.is_empty() {
                return Err(at.error(
                    span,
                    "signals.inputs",
                    "the FMU's inputs need a design: add an [input] (white, chicane or fixed)"
                        .into(),
                ));
            }
            if let (Some(_), true) = (input, signals.inputs.is_empty()) {
                return Err(at.error(
                    raw.input.as_ref().map(Spanned::span),
                    "input",
                    "[input] drives the measured inputs, but [signals] names none".into(),
                ));
            }
        }
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
            _ => spec,
        };
        let output_sd = at.output_noise(raw.noise.as_ref(), outputs.len())?;
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
            presets,
            name_lines,
            fmu_line,
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
                output_sd: self.output_sd.clone(),
            })),
            ModelSource::Command {
                command,
                dir,
                timeout,
                batch,
            } => {
                let mut external = ExternalSimulator::new(self.spec.clone(), command.clone())?
                    .timeout(*timeout)
                    .batch(*batch);
                if let Some(dir) = dir {
                    external = external.current_dir(dir);
                }
                Ok(Box::new(FileSimulator {
                    inner: Box::new(external),
                    spec: self.spec.clone(),
                    output_sd: self.output_sd.clone(),
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
                    output_sd: self.output_sd.clone(),
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
            output_sd: self.output_sd.clone(),
        }))
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

/// A model file to start from for an FMU, as `twostage fmu inspect
/// --write` saves it: every fixed or tunable real parameter with a uniform
/// prior around its start value, the real inputs driven by white noise,
/// the real outputs measured, and the FMU's suggested step as the sample
/// time. Lines marked CHECK need a modeller's eye.
///
/// ```
/// use twostage_fmi::ModelDescription;
/// use twostage_sources::{fmu_model_file, ModelFile};
/// let xml = r#"<fmiModelDescription fmiVersion="2.0" modelName="tank" guid="{1}">
///   <CoSimulation modelIdentifier="tank"/>
///   <DefaultExperiment stopTime="50" stepSize="0.1"/>
///   <ModelVariables>
///     <ScalarVariable name="area" valueReference="0" causality="parameter" variability="fixed">
///       <Real start="2.0" unit="m2"/></ScalarVariable>
///     <ScalarVariable name="inflow" valueReference="1" causality="input"><Real start="0"/></ScalarVariable>
///     <ScalarVariable name="level" valueReference="2" causality="output"><Real/></ScalarVariable>
///   </ModelVariables>
/// </fmiModelDescription>"#;
/// let text = fmu_model_file(&ModelDescription::parse(xml, "tank.fmu")?, "tank.fmu");
/// let file = ModelFile::parse(&text, "tank.toml").expect("the starting file parses");
/// assert_eq!(file.spec().param_names(), ["area"]);
/// assert_eq!(file.spec().n_samples(), 500);
/// # Ok::<(), twostage_fmi::FmiError>(())
/// ```
pub fn fmu_model_file(description: &twostage_fmi::ModelDescription, fmu: &str) -> String {
    use std::fmt::Write;
    use twostage_fmi::{Causality, Variability};
    let md = description;
    let real = |c: Causality| {
        md.variables
            .iter()
            .filter(move |v| v.is_real_scalar && v.causality == c)
    };
    let parameters: Vec<_> = real(Causality::Parameter)
        .filter(|v| matches!(v.variability, Variability::Fixed | Variability::Tunable))
        .collect();
    let inputs: Vec<&str> = real(Causality::Input).map(|v| v.name.as_str()).collect();
    let outputs: Vec<&str> = real(Causality::Output).map(|v| v.name.as_str()).collect();
    let step = md
        .default_experiment
        .step_size
        .filter(|h| h.is_finite() && *h > 0.0);
    let sample_time = step.unwrap_or(0.01);
    let span = md
        .default_experiment
        .stop_time
        .map(|stop| stop - md.default_experiment.start_time.unwrap_or(0.0));
    let samples = span
        .map(|t| (t / sample_time).round())
        .filter(|n| n.is_finite() && (2.0..=1e6).contains(n))
        .map_or(1000, |n| n as usize);
    let quote = |s: &str| format!("{s:?}");
    let list = |names: &[&str]| {
        names
            .iter()
            .map(|n| quote(n))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"# A starting model file for the FMU {name}, written by `twostage fmu inspect`.
# Lines marked CHECK are guesses: set them from what you know of the model.
# The reference is `twostage models --template`; docs/fmu.md walks through it.

[model]
name = {name}"#,
        name = quote(&md.model_name)
    );
    if let Some(d) = &md.description {
        let _ = writeln!(out, "description = {}", quote(d));
    }
    let interface = if md.co_simulation.is_some() {
        "co-simulation"
    } else {
        "model-exchange"
    };
    let _ = writeln!(
        out,
        r#"
[source]
fmu = {fmu}
interface = "{interface}"
step_divisor = 1                   # CHECK: doStep (or RK4 steps) per sample

# The parameters to estimate: delete those you know (they keep their start
# values, or set them with start = {{ name = value }} under [source])."#,
        fmu = quote(fmu)
    );
    if parameters.is_empty() {
        let _ = writeln!(
            out,
            r#"# The FMU has no fixed or tunable real parameter: nothing to estimate as is.
[[parameter]]
name = "CHECK"
prior = {{ dist = "uniform", low = 0.0, high = 1.0 }}"#
        );
    }
    for v in &parameters {
        let start = v.start.filter(|s| s.is_finite()).unwrap_or(0.0);
        // Half to one and a half times the start value: a guess to replace.
        let (low, high) = if start.abs() > 0.0 {
            let (a, b) = (0.5 * start, 1.5 * start);
            (a.min(b), a.max(b))
        } else {
            (-1.0, 1.0)
        };
        let note = match (&v.unit, &v.description) {
            (Some(u), Some(d)) => format!(" ({u}): {d}"),
            (Some(u), None) => format!(" ({u})"),
            (None, Some(d)) => format!(": {d}"),
            (None, None) => String::new(),
        };
        let _ = writeln!(
            out,
            r#"[[parameter]]
name = {name}
# CHECK: start value {start}{note}
prior = {{ dist = "uniform", low = {low:?}, high = {high:?} }}"#,
            name = quote(&v.name)
        );
    }
    let _ = writeln!(
        out,
        r#"
[signals]
inputs = [{inputs}]
outputs = [{outputs}]{no_output}
samples = {samples}                    # CHECK: record length
sample_time = {sample_time:?}{step_note}"#,
        inputs = list(&inputs),
        outputs = list(&outputs),
        no_output = if outputs.is_empty() {
            "  # CHECK: the FMU declares no real output; name what is measured"
        } else {
            ""
        },
        step_note = if step.is_some() {
            "                 # the FMU's suggested step"
        } else {
            "                 # CHECK: the FMU suggests no step"
        }
    );
    if !inputs.is_empty() {
        let _ = writeln!(
            out,
            r#"
# CHECK: the input of every experiment (white, chicane or fixed). Inputs
# that are disturbances go under [noise] inputs = [{{ name = ..., sd = ... }}].
[input]
signal = "white"
sd = 1.0"#
        );
    }
    let compress = if inputs.is_empty() { "ar:4" } else { "arx:4,4" };
    let _ = writeln!(
        out,
        r#"
[[preset]]
name = "default"
compress = "{compress}"
fit = "mlp:10"
sims = 2000"#
    );
    out
}

/// A model file's simulator: the source's, under the file's name, prior
/// and signal names, with the file's measurement noise added.
struct FileSimulator {
    inner: Box<dyn Simulator>,
    spec: ModelSpec,
    output_sd: Vec<f64>,
}

impl Simulator for FileSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        self.inner.simulate(theta, rng, out)?;
        self.measured(rng, out)
    }

    fn batch_size(&self) -> usize {
        self.inner.batch_size()
    }

    fn simulate_batch(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        outs: &mut [IoData],
    ) -> Vec<twostage_models::Result<()>> {
        let mut results = self.inner.simulate_batch(thetas, rngs, outs);
        for ((result, rng), out) in results.iter_mut().zip(rngs.iter_mut()).zip(outs.iter_mut()) {
            if result.is_ok() {
                *result = self.measured(rng, out);
            }
        }
        results
    }
}

impl FileSimulator {
    /// Check the source's record against the file and add the file's
    /// measurement noise.
    fn measured(&self, rng: &mut ExperimentRng, out: &mut IoData) -> twostage_models::Result<()> {
        let (n, want) = (out.n_samples(), self.spec.n_samples());
        if n != want || out.n_outputs() != self.output_sd.len() {
            return Err(twostage_models::SimError::InvalidData(format!(
                "the source gave {n} samples of {} outputs, the model file says {want} of {}",
                out.n_outputs(),
                self.output_sd.len()
            )));
        }
        // After the source's own draws, from the same stream: experiment i
        // of seed s stays the same bits.
        for (j, &sd) in self.output_sd.iter().enumerate() {
            if sd > 0.0 {
                for y in out.output_mut(j) {
                    let e: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng);
                    *y += sd * e;
                }
            }
        }
        Ok(())
    }
}

/// The model of a file without a source: a spec, and a refusal to simulate.
struct ChartsOnly {
    spec: ModelSpec,
    origin: String,
}

impl Simulator for ChartsOnly {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate(
        &self,
        _: &[f64],
        _: &mut ExperimentRng,
        _: &mut IoData,
    ) -> twostage_models::Result<()> {
        Err(twostage_models::SimError::InvalidData(format!(
            "{} has no [source]: its charts come from files, it cannot simulate",
            self.origin
        )))
    }
}

// ---- The file as TOML gives it (unknown keys are refused with their line).

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    model: RawModel,
    source: Option<Spanned<RawSource>>,
    #[serde(default)]
    parameter: Vec<Spanned<RawParameter>>,
    signals: Option<Spanned<RawSignals>>,
    input: Option<Spanned<RawInput>>,
    noise: Option<Spanned<RawNoise>>,
    #[serde(default)]
    preset: Vec<Spanned<RawPreset>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    name: Spanned<String>,
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSource {
    builtin: Option<Spanned<String>>,
    command: Option<Spanned<Vec<String>>>,
    fmu: Option<Spanned<String>>,
    timeout_seconds: Option<Spanned<f64>>,
    batch: Option<Spanned<i64>>,
    interface: Option<Spanned<String>>,
    step_divisor: Option<Spanned<i64>>,
    start_time: Option<Spanned<f64>>,
    start: Option<Spanned<BTreeMap<String, f64>>>,
}

impl RawSource {
    /// The first key given that only an FMU source takes.
    fn fmu_key(&self) -> Option<(&'static str, Range<usize>)> {
        [
            (
                "source.interface",
                self.interface.as_ref().map(Spanned::span),
            ),
            (
                "source.step_divisor",
                self.step_divisor.as_ref().map(Spanned::span),
            ),
            (
                "source.start_time",
                self.start_time.as_ref().map(Spanned::span),
            ),
            ("source.start", self.start.as_ref().map(Spanned::span)),
        ]
        .into_iter()
        .find_map(|(key, span)| span.map(|s| (key, s)))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParameter {
    name: Spanned<String>,
    prior: Option<Spanned<RawPrior>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPrior {
    dist: Spanned<String>,
    low: Option<f64>,
    high: Option<f64>,
    mu: Option<f64>,
    sigma: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSignals {
    inputs: Option<Spanned<Vec<String>>>,
    outputs: Option<Spanned<Vec<String>>>,
    samples: Option<Spanned<i64>>,
    sample_time: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInput {
    signal: Spanned<String>,
    sd: Option<f64>,
    amplitude: Option<f64>,
    values: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    model: Option<bool>,
    output_sd: Option<Spanned<OneOrMany>>,
    inputs: Option<Spanned<Vec<RawNoiseInput>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoiseInput {
    name: String,
    sd: f64,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    One(f64),
    Many(Vec<f64>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPreset {
    name: Spanned<String>,
    compress: Spanned<String>,
    fit: Spanned<String>,
    sims: Option<Spanned<i64>>,
}

/// The checked signals.
struct Signals {
    inputs: Vec<String>,
    outputs: Vec<String>,
    samples: usize,
    sample_time: f64,
}

/// Turns byte spans into lines and builds errors.
struct Locator<'t> {
    text: &'t str,
    origin: &'t str,
}

impl Locator<'_> {
    fn line(&self, offset: usize) -> usize {
        1 + self.text.as_bytes()[..offset.min(self.text.len())]
            .iter()
            .filter(|b| **b == b'\n')
            .count()
    }

    fn error(&self, span: Option<Range<usize>>, key: &str, message: String) -> Error {
        Error::ModelFile {
            file: self.origin.to_string(),
            line: span.map(|s| self.line(s.start)),
            key: key.to_string(),
            message,
        }
    }

    fn source(
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
        let model: BuiltinModel =
            name.get_ref()
                .parse()
                .map_err(|e: twostage_models::SimError| {
                    self.error(Some(name.span()), "source.builtin", e.to_string())
                })?;
        let noiseless = noise.is_some_and(|n| n.get_ref().model == Some(false));
        let input = input.map(|i| self.input(i)).transpose()?;
        Ok(ModelSource::Builtin {
            model,
            overrides: BuiltinOverrides {
                noiseless,
                n_samples: None,
                input,
            },
        })
    }

    fn one_source(&self, span: Range<usize>) -> Error {
        self.error(
            Some(span),
            "source",
            "give one source: builtin = \"benchmark\" (or \"pacejka\"), command = \
             [\"python3\", \"sim.py\"] (docs/protocol.md), or fmu = \"model.fmu\" (docs/fmu.md)"
                .into(),
        )
    }

    fn fmu(
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
        Ok(ModelSource::Fmu {
            path: PathBuf::from(fmu.get_ref()),
            interface,
            step_divisor,
            start_time,
            starts,
            noise_inputs,
            input: input.map(|i| self.input(i)).transpose()?,
        })
    }

    /// Where the names a source must know were written.
    fn name_lines(&self, raw: &RawFile) -> Vec<(String, &'static str, usize)> {
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

    fn command(
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
        if let Some(input) = input {
            return Err(self.error(
                Some(input.span()),
                "input",
                "a command makes its own input and returns it with the outputs: leave [input] out"
                    .into(),
            ));
        }
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
        })
    }

    fn input(&self, input: &Spanned<RawInput>) -> Result<InputSignal> {
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

    fn parameters(
        &self,
        raw: &[Spanned<RawParameter>],
        base: Option<&ModelSpec>,
    ) -> Result<(Vec<String>, Vec<Marginal>)> {
        if let Some(base) = base {
            if raw.is_empty() {
                return Ok((
                    base.param_names().to_vec(),
                    base.prior().marginals().to_vec(),
                ));
            }
            if raw.len() != base.n_params() {
                return Err(self.error(
                    Some(raw[0].span()),
                    "parameter",
                    format!(
                        "the built-in source has {} parameter(s) ({}); give one [[parameter]] \
                         each, in that order, or none to keep its priors",
                        base.n_params(),
                        base.param_names().join(", ")
                    ),
                ));
            }
        } else if raw.is_empty() {
            return Err(self.error(
                None,
                "parameter",
                "no [[parameter]]: give each parameter a name and a prior".into(),
            ));
        }
        let mut names = Vec::with_capacity(raw.len());
        let mut marginals = Vec::with_capacity(raw.len());
        for (j, p) in raw.iter().enumerate() {
            let p_ref = p.get_ref();
            let name = p_ref.name.get_ref().trim().to_string();
            if name.is_empty() || names.contains(&name) {
                return Err(self.error(
                    Some(p_ref.name.span()),
                    "parameter.name",
                    format!("'{name}' is empty or used twice: every parameter needs its own name"),
                ));
            }
            let marginal = match (&p_ref.prior, base) {
                (Some(prior), _) => self.marginal(prior, &name, j)?,
                (None, Some(base)) => base.prior().marginals()[j],
                (None, None) => {
                    return Err(self.error(
                        Some(p.span()),
                        "parameter.prior",
                        format!(
                            "parameter '{name}' has no prior: add prior = {{ dist = \"uniform\", \
                             low = ..., high = ... }} (or normal, lognormal, truncnormal)"
                        ),
                    ));
                }
            };
            names.push(name);
            marginals.push(marginal);
        }
        Ok((names, marginals))
    }

    fn marginal(&self, prior: &Spanned<RawPrior>, name: &str, index: usize) -> Result<Marginal> {
        let raw = prior.get_ref();
        let dist = raw.dist.get_ref().as_str();
        let key = "parameter.prior";
        let needs: &[&str] = match dist {
            "uniform" => &["low", "high"],
            "normal" | "lognormal" => &["mu", "sigma"],
            "truncnormal" => &["mu", "sigma", "low", "high"],
            other => {
                return Err(self.error(
                    Some(raw.dist.span()),
                    "parameter.prior.dist",
                    format!(
                        "parameter '{name}': unknown distribution '{other}': use uniform, \
                         normal, lognormal or truncnormal"
                    ),
                ));
            }
        };
        let given = [
            ("low", raw.low),
            ("high", raw.high),
            ("mu", raw.mu),
            ("sigma", raw.sigma),
        ];
        for (k, v) in given {
            if v.is_some() != needs.contains(&k) {
                return Err(self.error(
                    Some(prior.span()),
                    &format!("{key}.{k}"),
                    format!(
                        "parameter '{name}': a {dist} prior takes exactly {}",
                        needs.join(", ")
                    ),
                ));
            }
        }
        let v = |x: Option<f64>| x.unwrap_or(f64::NAN);
        let marginal = match dist {
            "uniform" => Marginal::Uniform {
                low: v(raw.low),
                high: v(raw.high),
            },
            "normal" => Marginal::Normal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
            },
            "lognormal" => Marginal::LogNormal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
            },
            _ => Marginal::TruncatedNormal {
                mu: v(raw.mu),
                sigma: v(raw.sigma),
                low: v(raw.low),
                high: v(raw.high),
            },
        };
        marginal
            .check(index)
            .map_err(|e| self.error(Some(prior.span()), key, format!("parameter '{name}': {e}")))?;
        Ok(marginal)
    }

    fn signals(
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
        let names = |given: &Option<Spanned<Vec<String>>>,
                     key: &str,
                     base: Option<&[String]>|
         -> Result<Vec<String>> {
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
                                format!(
                                    "'{n}' is empty or used twice: each signal needs its own name"
                                ),
                            ));
                        }
                        seen.push(n);
                    }
                    Ok(list.get_ref().clone())
                }
                (None, Some(base)) => Ok(base.to_vec()),
                (None, None) if key == "signals.inputs" => Ok(Vec::new()),
                (None, None) => Err(self.error(
                    whole.clone(),
                    key,
                    "name the measured outputs, e.g. outputs = [\"y\"]".into(),
                )),
            }
        };
        let inputs = names(
            &s.inputs,
            "signals.inputs",
            base.map(ModelSpec::input_names),
        )?;
        let outputs = names(
            &s.outputs,
            "signals.outputs",
            base.map(ModelSpec::output_names),
        )?;
        if outputs.is_empty() {
            return Err(self.error(
                whole,
                "signals.outputs",
                "at least one output: an estimator learns from what is measured".into(),
            ));
        }
        let samples = match (&s.samples, base) {
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
                })?,
            (None, Some(base)) => base.n_samples(),
            (None, None) => {
                return Err(self.error(
                    whole,
                    "signals.samples",
                    "give the record length, samples = N".into(),
                ));
            }
        };
        let sample_time = match (&s.sample_time, base) {
            (Some(t), Some(base)) if t.get_ref().to_bits() != base.sample_time().to_bits() => {
                return Err(self.error(
                    Some(t.span()),
                    "signals.sample_time",
                    format!(
                        "the built-in source samples every {}: leave sample_time out",
                        base.sample_time()
                    ),
                ));
            }
            (Some(t), _) if !(t.get_ref().is_finite() && *t.get_ref() > 0.0) => {
                return Err(self.error(
                    Some(t.span()),
                    "signals.sample_time",
                    format!("{}: give a finite time > 0 between samples", t.get_ref()),
                ));
            }
            (Some(t), _) => *t.get_ref(),
            (None, Some(base)) => base.sample_time(),
            (None, None) => 1.0,
        };
        Ok(Signals {
            inputs,
            outputs,
            samples,
            sample_time,
        })
    }

    fn output_noise(&self, noise: Option<&Spanned<RawNoise>>, outputs: usize) -> Result<Vec<f64>> {
        let Some(sd) = noise.and_then(|n| n.get_ref().output_sd.as_ref()) else {
            return Ok(vec![0.0; outputs]);
        };
        let values = match sd.get_ref() {
            OneOrMany::One(v) => vec![*v; outputs],
            OneOrMany::Many(v) => v.clone(),
        };
        if values.len() != outputs || values.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(self.error(
                Some(sd.span()),
                "noise.output_sd",
                format!(
                    "{values:?}: give one standard deviation >= 0 for all outputs, or a list of \
                     {outputs} (one per output)"
                ),
            ));
        }
        Ok(values)
    }

    fn presets(&self, raw: &[Spanned<RawPreset>]) -> Result<Vec<(String, Preset)>> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_template_is_a_valid_model_file() {
        let file = ModelFile::parse(TEMPLATE, "template.toml").unwrap();
        assert!(file.simulator().is_ok());
        assert!(file.preset_names().count() >= 1);
    }
}
