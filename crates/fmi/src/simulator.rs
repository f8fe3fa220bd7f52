//! An FMU behind the [`Simulator`] trait.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{
    ExperimentRng, InputSignal, IoData, ModelSpec, OdeSystem, Rk4, SimError, Simulator,
};

use crate::archive::Unpacked;
use crate::description::{
    Causality, Interface, InterfaceKind, ModelDescription, Variability, Variable,
};
use crate::error::{FmiError, Result};
use crate::ffi::{Binary, Component};
use crate::worker::WorkerPool;

/// The most communication (or integration) steps per sample.
const MAX_STEP_DIVISOR: usize = 1 << 16;

/// An FMU opened for inspection: its description, without loading its
/// binary.
///
/// ```no_run
/// let fmu = twostage_fmi::Fmu::open("car.fmu")?;
/// for v in &fmu.description().variables {
///     println!("{} ({})", v.name, v.causality.as_str());
/// }
/// # Ok::<(), twostage_fmi::FmiError>(())
/// ```
#[derive(Debug)]
pub struct Fmu {
    unpacked: Unpacked,
}

impl Fmu {
    /// Unpack an FMU (a `.fmu` archive or an unpacked folder) and read its
    /// `modelDescription.xml`.
    ///
    /// # Errors
    /// [`FmiError::Io`], [`FmiError::NotAnArchive`],
    /// [`FmiError::Description`] or [`FmiError::UnsupportedVersion`].
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        Ok(Self {
            unpacked: Unpacked::open(path.as_ref())?,
        })
    }

    /// What the FMU says about itself.
    pub fn description(&self) -> &ModelDescription {
        &self.unpacked.description
    }
}

/// What the FMU is asked to do, by variable name: everything a worker
/// process needs to set up the same simulation.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct Setup {
    pub path: PathBuf,
    pub parameters: Vec<String>,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    pub noise_inputs: Vec<(String, f64)>,
    pub starts: Vec<(String, f64)>,
    pub interface: Option<InterfaceKind>,
    pub step_divisor: usize,
    pub start_time: f64,
    pub sample_time: f64,
    pub n_samples: usize,
}

/// The program every once-per-process FMU runs its worker processes with,
/// unless its builder names one.
static WORKER_COMMAND: OnceLock<Vec<String>> = OnceLock::new();

/// Run FMUs that may be instantiated only once per process in worker
/// processes started with `command`, a program that calls
/// [`serve_worker`](crate::serve_worker) on its stdin and stdout (the
/// `twostage` binary: `["twostage", "fmu", "worker"]`). The first call
/// wins. Without it such FMUs run one experiment at a time in this process.
///
/// ```
/// twostage_fmi::use_worker_processes(vec!["twostage".into(), "fmu".into(), "worker".into()]);
/// ```
pub fn use_worker_processes(command: Vec<String>) {
    let _ = WORKER_COMMAND.set(command);
}

/// How an [`FmuSimulator`] drives its FMU; see [`FmuSimulator::builder`].
#[derive(Debug, Clone)]
pub struct FmuSimulatorBuilder {
    setup: Setup,
    spec: ModelSpec,
    input: Option<InputSignal>,
    workers: Option<Vec<String>>,
}

impl FmuSimulatorBuilder {
    /// The input design that drives the FMU's inputs (the spec's input
    /// names), each input drawn in turn from the experiment's stream.
    pub fn input(mut self, input: InputSignal) -> Self {
        self.input = Some(input);
        self
    }

    /// Drive the FMU input `name` with white Gaussian noise of standard
    /// deviation `sd` (process or measurement noise the FMU adds itself),
    /// drawn from the experiment's stream: sample by sample, in the order
    /// the noise inputs were named.
    pub fn noise_input(mut self, name: &str, sd: f64) -> Self {
        self.setup.noise_inputs.push((name.to_string(), sd));
        self
    }

    /// Set the FMU variable `name` (a parameter, or an input's start) to
    /// `value` before initialization, in every experiment.
    pub fn start(mut self, name: &str, value: f64) -> Self {
        self.setup.starts.push((name.to_string(), value));
        self
    }

    /// Co-simulation or model exchange (default: co-simulation if the FMU
    /// has it).
    pub fn interface(mut self, kind: InterfaceKind) -> Self {
        self.setup.interface = Some(kind);
        self
    }

    /// Communication steps (co-simulation) or RK4 steps (model exchange)
    /// per sample.
    pub fn step_divisor(mut self, divisor: usize) -> Self {
        self.setup.step_divisor = divisor;
        self
    }

    /// The simulation time of the first sample.
    pub fn start_time(mut self, time: f64) -> Self {
        self.setup.start_time = time;
        self
    }

    /// The worker program for an FMU that may be instantiated only once
    /// per process (see [`use_worker_processes`]); ignored for others.
    pub fn worker_processes(mut self, command: Vec<String>) -> Self {
        self.workers = Some(command);
        self
    }

    /// Open the FMU, check every name against its description, load its
    /// binary and instantiate it once.
    ///
    /// | setting | default | valid |
    /// |---|---|---|
    /// | `interface` | co-simulation if present | one the FMU declares |
    /// | `step_divisor` | 1 | 1 to 65536 |
    /// | `start_time` | 0 | finite |
    /// | `noise_input` sd | none | finite, >= 0 |
    ///
    /// # Errors
    /// Everything [`Fmu::open`] reports; [`FmiError::Variable`] for a name
    /// the FMU lacks or whose role does not fit (a parameter that is not a
    /// fixed or tunable real parameter, an input that is not a real input,
    /// an output that is not a real output or local); [`FmiError::Interface`]
    /// for a missing interface or a model-exchange FMU with state events;
    /// [`FmiError::NoBinary`] and [`FmiError::Binary`] for the binary;
    /// [`FmiError::Setting`] for settings out of range.
    pub fn build(self) -> Result<FmuSimulator> {
        let loaded = Loaded::open(&self.setup)?;
        if !self.spec.input_names().is_empty() && self.input.is_none() {
            return Err(FmiError::Setting {
                name: "input",
                value: self.spec.input_names().join(", "),
                reason: "the FMU's inputs need an input design (white, chicane or fixed)".into(),
            });
        }
        let single = loaded.interface.once_per_process || loaded.interface.needs_execution_tool;
        let workers = self.workers.or_else(|| WORKER_COMMAND.get().cloned());
        let engine = match workers {
            Some(command) if single => Engine::Workers(Box::new(WorkerPool::start(
                command,
                &self.setup,
                &loaded.unpacked.origin,
            )?)),
            _ => Engine::InProcess(loaded.in_process(single)?),
        };
        Ok(FmuSimulator {
            noise_sd: self.setup.noise_inputs.iter().map(|(_, sd)| *sd).collect(),
            spec: self.spec,
            input: self.input,
            plan: loaded.plan,
            engine,
            unpacked: Arc::new(loaded.unpacked),
        })
    }
}

/// An FMU opened and checked against a [`Setup`]: its description, the
/// interface in use and the plan of an experiment.
pub(crate) struct Loaded {
    pub unpacked: Unpacked,
    pub interface: Interface,
    pub plan: Plan,
}

impl Loaded {
    pub fn open(setup: &Setup) -> Result<Self> {
        let unpacked = Unpacked::open(&setup.path)?;
        let origin = unpacked.origin.clone();
        if !(1..=MAX_STEP_DIVISOR).contains(&setup.step_divisor) {
            return Err(FmiError::Setting {
                name: "step_divisor",
                value: setup.step_divisor.to_string(),
                reason: format!("give 1 to {MAX_STEP_DIVISOR} steps per sample"),
            });
        }
        if !setup.start_time.is_finite() {
            return Err(FmiError::Setting {
                name: "start_time",
                value: setup.start_time.to_string(),
                reason: "must be finite".into(),
            });
        }
        let md = &unpacked.description;
        let kind = match setup.interface {
            Some(kind) => kind,
            None if md.co_simulation.is_some() => InterfaceKind::CoSimulation,
            None => InterfaceKind::ModelExchange,
        };
        let interface = md
            .interface(kind)
            .ok_or_else(|| FmiError::Interface {
                path: origin.clone(),
                message: format!(
                    "the FMU has no {kind} interface; it has {}",
                    if md.co_simulation.is_some() {
                        "co-simulation"
                    } else {
                        "model exchange"
                    }
                ),
            })?
            .clone();
        if kind == InterfaceKind::ModelExchange && md.event_indicators > 0 {
            return Err(FmiError::Interface {
                path: origin,
                message: format!(
                    "the model-exchange FMU has {} event indicator(s) (state events), which a \
                     fixed-step integrator cannot locate: it would be simulated wrongly. Use its \
                     co-simulation interface if it has one, or export it for co-simulation",
                    md.event_indicators
                ),
            });
        }
        let roles = Roles::check(md, &origin, setup)?;
        // FMI 2.0 co-simulation FMUs that say they interpolate inputs get
        // the straight line to the next sample (the project's convention
        // for continuous-time models, decision 005); FMI 3.0 has no input
        // derivatives, and others hold inputs between samples.
        let interpolate_inputs = md.version == crate::FmiVersion::V2
            && kind == InterfaceKind::CoSimulation
            && md.can_interpolate_inputs
            && !setup.inputs.is_empty();
        let plan = Plan {
            roles,
            kind,
            interpolate_inputs,
            step_divisor: setup.step_divisor,
            start_time: setup.start_time,
            sample_time: setup.sample_time,
            continuous_states: md.continuous_states,
            origin,
        };
        Ok(Self {
            unpacked,
            interface,
            plan,
        })
    }

    /// Load the binary and instantiate it once, so that a token mismatch
    /// or a missing resource is reported before any experiment.
    pub fn in_process(&self, serial: bool) -> Result<InProcess> {
        let md = &self.unpacked.description;
        let binary = self.unpacked.binary(&self.interface.model_identifier)?;
        let binary = Arc::new(Binary::load(
            &binary,
            md.version,
            self.plan.kind,
            self.plan.interpolate_inputs,
            &self.unpacked.origin,
            &md.token,
            &self.unpacked.resource_location(),
        )?);
        let engine = InProcess {
            binary,
            serial,
            idle: Mutex::new(Vec::new()),
            instances: AtomicUsize::new(0),
        };
        let first = engine.instantiate()?;
        engine.give_back(first);
        Ok(engine)
    }
}

/// The value references of each role.
#[derive(Debug, Clone)]
struct Roles {
    parameters: Vec<u32>,
    /// The measured inputs, then the noise inputs.
    inputs: Vec<u32>,
    n_measured_inputs: usize,
    outputs: Vec<u32>,
    start_references: Vec<u32>,
    start_values: Vec<f64>,
}

impl Roles {
    fn check(md: &ModelDescription, origin: &str, setup: &Setup) -> Result<Self> {
        let mut used: Vec<(&str, &str)> = Vec::new();
        let mut find = |name: &str, role: &'static str| -> Result<&Variable> {
            let variable = md.variable(name).ok_or_else(|| {
                let similar = md.similar_names(name);
                FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!(
                        "the FMU has no variable of that name{}; `twostage fmu inspect` lists them",
                        if similar.is_empty() {
                            String::new()
                        } else {
                            format!(" (similar: {})", similar.join(", "))
                        }
                    ),
                }
            })?;
            if let Some((_, other)) = used.iter().find(|(n, _)| *n == name) {
                return Err(FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!("named as {other} and as {role}: give each variable one role"),
                });
            }
            used.push((&variable.name, role));
            if !variable.is_real_scalar {
                return Err(FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!(
                        "it is a {}{}: twostage uses real scalar variables only",
                        variable.type_name,
                        if variable.type_name == "Float64" {
                            " array"
                        } else {
                            ""
                        }
                    ),
                });
            }
            Ok(variable)
        };
        let refuse = |v: &Variable, role: &str, wanted: &str| FmiError::Variable {
            path: origin.into(),
            name: v.name.clone(),
            message: format!(
                "it is a {} {} variable, so it cannot be {role}: {wanted}",
                v.variability.as_str(),
                v.causality.as_str()
            ),
        };
        let settable = |v: &Variable| {
            v.causality == Causality::Parameter
                && matches!(v.variability, Variability::Fixed | Variability::Tunable)
        };
        let mut parameters = Vec::new();
        for name in &setup.parameters {
            let v = find(name, "a parameter to estimate")?;
            if !settable(v) {
                return Err(refuse(
                    v,
                    "estimated",
                    "only a parameter with variability fixed or tunable can be set before \
                     initialization (a calculated parameter is computed from others: estimate \
                     those)",
                ));
            }
            parameters.push(v.value_reference);
        }
        let mut inputs = Vec::new();
        let noise_names = setup.noise_inputs.iter().map(|(n, _)| n);
        for (j, name) in setup.inputs.iter().chain(noise_names).enumerate() {
            let role = if j < setup.inputs.len() {
                "an input"
            } else {
                "a noise input"
            };
            let v = find(name, role)?;
            if v.causality != Causality::Input {
                return Err(refuse(v, role, "name one of the FMU's inputs"));
            }
            inputs.push(v.value_reference);
        }
        for (name, sd) in &setup.noise_inputs {
            if !(sd.is_finite() && *sd >= 0.0) {
                return Err(FmiError::Setting {
                    name: "noise input sd",
                    value: format!("{name} = {sd}"),
                    reason: "must be finite and >= 0".into(),
                });
            }
        }
        let mut outputs = Vec::new();
        for name in &setup.outputs {
            let v = find(name, "an output")?;
            if !matches!(v.causality, Causality::Output | Causality::Local) {
                return Err(refuse(
                    v,
                    "measured",
                    "name an output (or a local variable)",
                ));
            }
            outputs.push(v.value_reference);
        }
        let (mut start_references, mut start_values) = (Vec::new(), Vec::new());
        for (name, value) in &setup.starts {
            let v = find(name, "a start value")?;
            if !(settable(v) || v.causality == Causality::Input) {
                return Err(refuse(
                    v,
                    "given a start value",
                    "name a fixed or tunable parameter",
                ));
            }
            if !value.is_finite() {
                return Err(FmiError::Setting {
                    name: "start value",
                    value: format!("{name} = {value}"),
                    reason: "must be finite".into(),
                });
            }
            start_references.push(v.value_reference);
            start_values.push(*value);
        }
        Ok(Self {
            parameters,
            n_measured_inputs: setup.inputs.len(),
            inputs,
            outputs,
            start_references,
            start_values,
        })
    }
}

/// An FMU as a simulator: the parameters are set before initialization,
/// the inputs come from the input design and the noise inputs from the
/// experiment's stream, and the outputs are read at every sample.
///
/// Each worker thread gets its own instance (reset and reused between
/// experiments). An FMU that may be instantiated only once per process runs
/// in worker processes, one instance each, if a worker program is known
/// ([`use_worker_processes`]), and otherwise one experiment at a time.
/// Either way, experiment `i` of seed `s` is the same bits whatever the
/// thread count: everything random is drawn from the experiment's stream
/// before the FMU runs.
///
/// ```no_run
/// use twostage_fmi::FmuSimulator;
/// use twostage_models::{experiment_rng, InputSignal, ModelSpec, Prior, Simulator};
/// let spec = ModelSpec::new("tank", &["area"], Prior::uniform_box(&[0.5], &[2.0])?, 0.1, 500)?
///     .with_signals(&["inflow"], &["level"]);
/// let tank = FmuSimulator::builder("tank.fmu", spec)
///     .input(InputSignal::white_gaussian(1.0)?)
///     .build()?;
/// let mut record = tank.spec().new_record();
/// tank.simulate(&[1.2], &mut experiment_rng(1, 0), &mut record)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct FmuSimulator {
    spec: ModelSpec,
    input: Option<InputSignal>,
    noise_sd: Vec<f64>,
    plan: Plan,
    engine: Engine,
    unpacked: Arc<Unpacked>,
}

/// Where experiments run.
enum Engine {
    InProcess(InProcess),
    Workers(Box<WorkerPool>),
}

impl std::fmt::Debug for FmuSimulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FmuSimulator")
            .field("fmu", &self.unpacked.origin)
            .field("interface", &self.plan.kind)
            .field("step_divisor", &self.plan.step_divisor)
            .field("execution", &self.execution())
            .finish_non_exhaustive()
    }
}

/// Where an [`FmuSimulator`] runs its experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Execution {
    /// One instance per worker thread, in this process.
    Threads,
    /// One instance, one experiment at a time (the FMU may be instantiated
    /// only once per process, and no worker program is known).
    OneAtATime,
    /// One instance in each of several worker processes.
    WorkerProcesses,
}

impl FmuSimulator {
    /// Simulate the FMU at `path` as the model `spec` describes: its
    /// parameter, input and output names are FMU variable names.
    pub fn builder(path: impl AsRef<Path>, spec: ModelSpec) -> FmuSimulatorBuilder {
        FmuSimulatorBuilder {
            setup: Setup {
                path: path.as_ref().to_path_buf(),
                parameters: spec.param_names().to_vec(),
                inputs: spec.input_names().to_vec(),
                outputs: spec.output_names().to_vec(),
                noise_inputs: Vec::new(),
                starts: Vec::new(),
                interface: None,
                step_divisor: 1,
                start_time: 0.0,
                sample_time: spec.sample_time(),
                n_samples: spec.n_samples(),
            },
            spec,
            input: None,
            workers: None,
        }
    }

    /// The FMU's description.
    pub fn description(&self) -> &ModelDescription {
        &self.unpacked.description
    }

    /// The interface in use.
    pub fn interface(&self) -> InterfaceKind {
        self.plan.kind
    }

    /// Whether the measured inputs follow the straight line between
    /// samples (an FMI 2.0 co-simulation FMU that can interpolate inputs)
    /// rather than being held.
    pub fn interpolates_inputs(&self) -> bool {
        self.plan.interpolate_inputs
    }

    /// Where experiments run.
    pub fn execution(&self) -> Execution {
        match &self.engine {
            Engine::InProcess(e) if e.serial => Execution::OneAtATime,
            Engine::InProcess(_) => Execution::Threads,
            Engine::Workers(_) => Execution::WorkerProcesses,
        }
    }
}

/// Instances in this process: one per concurrent caller, or one shared.
pub(crate) struct InProcess {
    binary: Arc<Binary>,
    serial: bool,
    idle: Mutex<Vec<Component>>,
    instances: AtomicUsize,
}

impl InProcess {
    /// Whether the FMU returned Fatal: this process cannot run it again.
    pub fn is_fatal(&self) -> bool {
        self.binary.is_fatal()
    }

    fn instantiate(&self) -> Result<Component> {
        let n = self.instances.fetch_add(1, Ordering::Relaxed);
        self.binary.instantiate(&format!("twostage-{n}"))
    }

    /// Keep an instance that finished its experiment, reset for the next.
    fn give_back(&self, mut component: Component) {
        if component.reset().is_ok() {
            self.idle
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(component);
        }
    }

    /// Run one experiment, the random draws done. An instance that failed
    /// is dropped: the next experiment gets a fresh one.
    pub fn run(&self, plan: &Plan, theta: &[f64], noise: &[f64], out: &mut IoData) -> Result<()> {
        if self.serial {
            // The lock is held for the whole experiment: one instance, one
            // experiment at a time.
            let mut idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
            let mut component = match idle.pop() {
                Some(c) => c,
                None => self.instantiate()?,
            };
            let result = plan.run(&mut component, theta, noise, out);
            if result.is_ok() && component.reset().is_ok() {
                idle.push(component);
            }
            return result;
        }
        let idle = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let mut component = match idle {
            Some(component) => component,
            None => self.instantiate()?,
        };
        let result = plan.run(&mut component, theta, noise, out);
        if result.is_ok() {
            self.give_back(component);
        }
        result
    }
}

/// How one experiment runs: value references and steps.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    roles: Roles,
    kind: InterfaceKind,
    /// Measured inputs follow the straight line between samples (FMI 2.0
    /// co-simulation with `canInterpolateInputs`).
    interpolate_inputs: bool,
    step_divisor: usize,
    start_time: f64,
    sample_time: f64,
    continuous_states: usize,
    origin: String,
}

impl Plan {
    /// Run one experiment on `component`: `out` holds the inputs, `noise`
    /// the noise inputs sample by sample; the outputs are written to `out`.
    fn run(
        &self,
        component: &mut Component,
        theta: &[f64],
        noise: &[f64],
        out: &mut IoData,
    ) -> Result<()> {
        let roles = &self.roles;
        component.set_reals(&roles.start_references, &roles.start_values)?;
        component.set_reals(&roles.parameters, theta)?;
        component.initialize(self.start_time)?;
        match self.kind {
            InterfaceKind::CoSimulation => self.co_simulate(component, noise, out),
            InterfaceKind::ModelExchange => self.integrate(component, noise, out),
        }
    }

    /// The number of noise inputs.
    pub fn noise_inputs(&self) -> usize {
        self.roles.inputs.len() - self.roles.n_measured_inputs
    }

    /// Set the inputs of sample `k` (measured, then noise) and read its
    /// outputs.
    fn sample(
        &self,
        component: &mut Component,
        k: usize,
        noise: &[f64],
        scratch: &mut Scratch,
        out: &mut IoData,
    ) -> Result<()> {
        let n_u = out.n_inputs();
        let n_noise = self.noise_inputs();
        for j in 0..n_u {
            scratch.inputs[j] = out.input(j)[k];
        }
        scratch.inputs[n_u..].copy_from_slice(&noise[k * n_noise..(k + 1) * n_noise]);
        component.set_reals(&self.roles.inputs, &scratch.inputs)?;
        component.get_reals(&self.roles.outputs, &mut scratch.outputs)?;
        for (j, &y) in scratch.outputs.iter().enumerate() {
            out.output_mut(j)[k] = y;
        }
        Ok(())
    }

    fn co_simulate(
        &self,
        component: &mut Component,
        noise: &[f64],
        out: &mut IoData,
    ) -> Result<()> {
        let n = out.n_samples();
        let mut scratch = Scratch::new(self.roles.inputs.len(), self.roles.outputs.len());
        let (d, step) = self.steps();
        let measured = &self.roles.inputs[..self.roles.n_measured_inputs];
        let mut slopes = vec![0.0; measured.len()];
        let mut values = vec![0.0; measured.len()];
        for k in 0..n {
            self.sample(component, k, noise, &mut scratch, out)?;
            if k + 1 == n {
                break;
            }
            if self.interpolate_inputs {
                for (j, slope) in slopes.iter_mut().enumerate() {
                    let u = out.input(j);
                    *slope = (u[k + 1] - u[k]) / self.sample_time;
                }
            }
            for s in 0..d {
                if self.interpolate_inputs {
                    if s > 0 {
                        // Within a sample, the value on the line at the
                        // sub-step's start.
                        for (j, value) in values.iter_mut().enumerate() {
                            *value = out.input(j)[k] + slopes[j] * (s as f64 * step);
                        }
                        component.set_reals(measured, &values)?;
                    }
                    component.set_input_slopes(measured, &slopes)?;
                }
                // From the step count, so time does not drift by rounding.
                component.do_step(self.start_time + (k * d + s) as f64 * step, step)?;
            }
        }
        Ok(())
    }

    /// Model exchange: the project's RK4, the inputs held over each sample.
    fn integrate(&self, component: &mut Component, noise: &[f64], out: &mut IoData) -> Result<()> {
        let mut next_event = component.update_discrete()?.next_event_time;
        let mut x = vec![0.0; self.continuous_states];
        component.get_states(&mut x)?;
        let n = out.n_samples();
        let mut scratch = Scratch::new(self.roles.inputs.len(), self.roles.outputs.len());
        let (d, step) = self.steps();
        let mut rk4 = Rk4::new(x.len());
        let t0 = self.start_time;
        for k in 0..n {
            component.set_time(t0 + (k * d) as f64 * step)?;
            component.set_states(&x)?;
            self.sample(component, k, noise, &mut scratch, out)?;
            if k + 1 == n {
                break;
            }
            for s in 0..d {
                let t = t0 + (k * d + s) as f64 * step;
                let end = t0 + (k * d + s + 1) as f64 * step;
                let system = Derivatives {
                    dim: x.len(),
                    component: RefCell::new(&mut *component),
                    failure: RefCell::new(None),
                };
                rk4.step(&system, t, step, &mut x);
                if let Some(failure) = system.failure.into_inner() {
                    return Err(failure);
                }
                component.set_time(end)?;
                component.set_states(&x)?;
                let mut event = component.completed_step()?;
                if let Some(at) = next_event {
                    let tolerance = 1e-9 * (step + end.abs());
                    if at < end - tolerance && at > t + tolerance {
                        return Err(FmiError::Interface {
                            path: self.origin.clone(),
                            message: format!(
                                "a time event at t = {at} falls inside the integration step \
                                 [{t}, {end}]; the fixed step cannot honour it. Choose a \
                                 sample time or step divisor that puts it on the grid, or use \
                                 co-simulation"
                            ),
                        });
                    }
                    event |= at <= end + tolerance;
                }
                if event {
                    component.enter_event_mode()?;
                    let update = component.update_discrete()?;
                    next_event = update.next_event_time;
                    if update.states_changed {
                        component.get_states(&mut x)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Steps per sample and their size.
    fn steps(&self) -> (usize, f64) {
        (
            self.step_divisor,
            self.sample_time / self.step_divisor as f64,
        )
    }
}

/// Per-experiment buffers for one sample's inputs and outputs.
struct Scratch {
    inputs: Vec<f64>,
    outputs: Vec<f64>,
}

impl Scratch {
    fn new(inputs: usize, outputs: usize) -> Self {
        Self {
            inputs: vec![0.0; inputs],
            outputs: vec![0.0; outputs],
        }
    }
}

/// A model-exchange instance as an ODE right-hand side for [`Rk4`]; the
/// first failing call is kept and reported after the step.
struct Derivatives<'c> {
    dim: usize,
    component: RefCell<&'c mut Component>,
    failure: RefCell<Option<FmiError>>,
}

impl OdeSystem for Derivatives<'_> {
    fn dim(&self) -> usize {
        self.dim
    }

    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
        if self.failure.borrow().is_some() {
            dx.fill(0.0);
            return;
        }
        let mut component = self.component.borrow_mut();
        let result = component
            .set_time(t)
            .and_then(|()| component.set_states(x))
            .and_then(|()| component.derivatives(dx));
        if let Err(e) = result {
            dx.fill(0.0);
            *self.failure.borrow_mut() = Some(e);
        }
    }
}

impl Simulator for FmuSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        let spec = &self.spec;
        spec.prior().check(theta, spec.param_names(), true)?;
        let n = spec.n_samples();
        out.resize(n, spec.input_names().len(), spec.output_names().len());
        // Every draw comes first, in a fixed order (each input whole, then
        // the noise inputs sample by sample), so that the FMU's run is a
        // function of the experiment's stream alone.
        if let Some(input) = &self.input {
            for j in 0..spec.input_names().len() {
                input.fill(spec.sample_time(), rng, out.input_mut(j))?;
            }
        }
        let mut noise = Vec::with_capacity(n * self.noise_sd.len());
        for _ in 0..n {
            for &sd in &self.noise_sd {
                let e: f64 = StandardNormal.sample(rng);
                noise.push(sd * e);
            }
        }
        match &self.engine {
            Engine::InProcess(engine) => engine.run(&self.plan, theta, &noise, out)?,
            Engine::Workers(pool) => pool.run(theta, &noise, out)?,
        }
        for j in 0..out.n_outputs() {
            if let Some(k) = out.output(j).iter().position(|y| !y.is_finite()) {
                return Err(SimError::Diverged {
                    theta: theta.to_vec(),
                    time: k as f64 * spec.sample_time(),
                });
            }
        }
        Ok(())
    }
}
