//! An FMU behind the [`Simulator`] trait.

use std::cell::RefCell;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{
    ExperimentRng, InputSignal, IoData, ModelSpec, OdeSystem, Rk4, SimError, Simulator,
};

use crate::archive::Unpacked;
use crate::description::{Causality, InterfaceKind, ModelDescription, Variability, Variable};
use crate::error::{FmiError, Result};
use crate::ffi::{Binary, Component};

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

/// How an [`FmuSimulator`] drives its FMU; see [`FmuSimulator::builder`].
#[derive(Debug, Clone)]
pub struct FmuSimulatorBuilder {
    path: std::path::PathBuf,
    spec: ModelSpec,
    input: Option<InputSignal>,
    noise_inputs: Vec<(String, f64)>,
    starts: Vec<(String, f64)>,
    interface: Option<InterfaceKind>,
    step_divisor: usize,
    start_time: f64,
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
        self.noise_inputs.push((name.to_string(), sd));
        self
    }

    /// Set the FMU variable `name` (a parameter, or an input's start) to
    /// `value` before initialization, in every experiment.
    pub fn start(mut self, name: &str, value: f64) -> Self {
        self.starts.push((name.to_string(), value));
        self
    }

    /// Co-simulation or model exchange (default: co-simulation if the FMU
    /// has it).
    pub fn interface(mut self, kind: InterfaceKind) -> Self {
        self.interface = Some(kind);
        self
    }

    /// Communication steps (co-simulation) or RK4 steps (model exchange)
    /// per sample.
    pub fn step_divisor(mut self, divisor: usize) -> Self {
        self.step_divisor = divisor;
        self
    }

    /// The simulation time of the first sample.
    pub fn start_time(mut self, time: f64) -> Self {
        self.start_time = time;
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
        let unpacked = Unpacked::open(&self.path)?;
        let origin = unpacked.origin.clone();
        if !(1..=MAX_STEP_DIVISOR).contains(&self.step_divisor) {
            return Err(FmiError::Setting {
                name: "step_divisor",
                value: self.step_divisor.to_string(),
                reason: format!("give 1 to {MAX_STEP_DIVISOR} steps per sample"),
            });
        }
        if !self.start_time.is_finite() {
            return Err(FmiError::Setting {
                name: "start_time",
                value: self.start_time.to_string(),
                reason: "must be finite".into(),
            });
        }
        let md = &unpacked.description;
        let kind = match self.interface {
            Some(kind) => kind,
            None if md.co_simulation.is_some() => InterfaceKind::CoSimulation,
            None => InterfaceKind::ModelExchange,
        };
        let interface = md.interface(kind).ok_or_else(|| FmiError::Interface {
            path: origin.clone(),
            message: format!(
                "the FMU has no {kind} interface; it has {}",
                if md.co_simulation.is_some() {
                    "co-simulation"
                } else {
                    "model exchange"
                }
            ),
        })?;
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
        let roles = Roles::check(md, &origin, &self)?;
        if !self.spec.input_names().is_empty() && self.input.is_none() {
            return Err(FmiError::Setting {
                name: "input",
                value: self.spec.input_names().join(", "),
                reason: "the FMU's inputs need an input design (white, chicane or fixed)".into(),
            });
        }
        let binary = unpacked.binary(&interface.model_identifier)?;
        let binary = Arc::new(Binary::load(
            &binary,
            md.version,
            kind,
            &origin,
            &md.token,
            &unpacked.resource_location(),
        )?);
        let simulator = FmuSimulator {
            spec: self.spec,
            input: self.input,
            noise_sd: self.noise_inputs.iter().map(|(_, sd)| *sd).collect(),
            roles,
            kind,
            step_divisor: self.step_divisor,
            start_time: self.start_time,
            continuous_states: md.continuous_states,
            serial: interface.once_per_process || interface.needs_execution_tool,
            idle: Mutex::new(Vec::new()),
            instances: AtomicUsize::new(0),
            binary,
            unpacked: Arc::new(unpacked),
        };
        // Instantiate once now, so that a token mismatch or a missing
        // resource is reported before any experiment.
        let first = simulator.instantiate()?;
        simulator.give_back(first);
        Ok(simulator)
    }
}

/// The value references of each role.
#[derive(Debug, Clone)]
struct Roles {
    parameters: Vec<u32>,
    /// The measured inputs, then the noise inputs.
    inputs: Vec<u32>,
    outputs: Vec<u32>,
    start_references: Vec<u32>,
    start_values: Vec<f64>,
}

impl Roles {
    fn check(md: &ModelDescription, origin: &str, setup: &FmuSimulatorBuilder) -> Result<Self> {
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
        for name in setup.spec.param_names() {
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
        for (j, name) in setup
            .spec
            .input_names()
            .iter()
            .chain(noise_names)
            .enumerate()
        {
            let role = if j < setup.spec.input_names().len() {
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
        for name in setup.spec.output_names() {
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
/// experiments); an FMU that may be instantiated only once per process
/// runs its experiments one at a time. Either way, experiment `i` of seed
/// `s` is the same bits whatever the thread count: everything random is
/// drawn from the experiment's stream before the FMU runs.
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
    roles: Roles,
    kind: InterfaceKind,
    step_divisor: usize,
    start_time: f64,
    continuous_states: usize,
    serial: bool,
    idle: Mutex<Vec<Component>>,
    instances: AtomicUsize,
    binary: Arc<Binary>,
    unpacked: Arc<Unpacked>,
}

impl std::fmt::Debug for FmuSimulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FmuSimulator")
            .field("fmu", &self.unpacked.origin)
            .field("interface", &self.kind)
            .field("step_divisor", &self.step_divisor)
            .field("one_at_a_time", &self.serial)
            .finish_non_exhaustive()
    }
}

impl FmuSimulator {
    /// Simulate the FMU at `path` as the model `spec` describes: its
    /// parameter, input and output names are FMU variable names.
    pub fn builder(path: impl AsRef<Path>, spec: ModelSpec) -> FmuSimulatorBuilder {
        FmuSimulatorBuilder {
            path: path.as_ref().to_path_buf(),
            spec,
            input: None,
            noise_inputs: Vec::new(),
            starts: Vec::new(),
            interface: None,
            step_divisor: 1,
            start_time: 0.0,
        }
    }

    /// The FMU's description.
    pub fn description(&self) -> &ModelDescription {
        &self.unpacked.description
    }

    /// The interface in use.
    pub fn interface(&self) -> InterfaceKind {
        self.kind
    }

    /// Whether experiments run one at a time (the FMU may be instantiated
    /// only once per process, or needs an external tool).
    pub fn one_at_a_time(&self) -> bool {
        self.serial
    }

    fn instantiate(&self) -> Result<Component> {
        let n = self.instances.fetch_add(1, Ordering::Relaxed);
        self.binary.instantiate(&format!("twostage-{n}"))
    }

    /// An instance ready for an experiment: an idle one, or a new one.
    fn take(&self) -> Result<Component> {
        let idle = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        match idle {
            Some(component) => Ok(component),
            None => self.instantiate(),
        }
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

    /// Run one experiment on `component`, the random draws done.
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
        let n_noise = self.noise_sd.len();
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
        for k in 0..n {
            self.sample(component, k, noise, &mut scratch, out)?;
            if k + 1 < n {
                for s in 0..d {
                    // From the step count, so time does not drift by rounding.
                    component.do_step(self.start_time + (k * d + s) as f64 * step, step)?;
                }
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
                            path: self.unpacked.origin.clone(),
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
            self.spec.sample_time() / self.step_divisor as f64,
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
        let _one_at_a_time = self
            .serial
            .then(|| self.idle.lock().unwrap_or_else(PoisonError::into_inner));
        let mut component = match _one_at_a_time {
            // The lock is held: use the one instance directly.
            Some(mut idle) => {
                let mut component = match idle.pop() {
                    Some(c) => c,
                    None => self.instantiate()?,
                };
                let result = self.run(&mut component, theta, &noise, out);
                if result.is_ok() && component.reset().is_ok() {
                    idle.push(component);
                }
                return finish(result, theta, spec.sample_time(), out);
            }
            None => self.take()?,
        };
        let result = self.run(&mut component, theta, &noise, out);
        if result.is_ok() {
            self.give_back(component);
        }
        finish(result, theta, spec.sample_time(), out)
    }
}

/// The experiment's result: the FMU's error, or a diverged record.
fn finish(
    result: Result<()>,
    theta: &[f64],
    sample_time: f64,
    out: &IoData,
) -> twostage_models::Result<()> {
    result?;
    for j in 0..out.n_outputs() {
        if let Some(k) = out.output(j).iter().position(|y| !y.is_finite()) {
            return Err(SimError::Diverged {
                theta: theta.to_vec(),
                time: k as f64 * sample_time,
            });
        }
    }
    Ok(())
}
