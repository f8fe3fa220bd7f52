//! An FMU behind the [`Simulator`] trait.

use std::path::Path;
use std::sync::Arc;

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{
    Capabilities, Conditions, ExperimentRng, InputSignal, IoData, ModelSpec, SimError, Simulator,
};

use crate::archive::Unpacked;
use crate::description::{InterfaceKind, ModelDescription};
use crate::error::{FmiError, Result};
use crate::run::{InProcess, Plan};
use crate::setup::{Loaded, Setup};
use crate::worker::WorkerPool;

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

    /// The shared library this platform would load (of the co-simulation
    /// interface, else model exchange), without loading it.
    ///
    /// # Errors
    /// [`FmiError::NoBinary`] naming the file looked for and the platforms
    /// the FMU has: it cannot be simulated here.
    pub fn binary_here(&self) -> Result<std::path::PathBuf> {
        let md = &self.unpacked.description;
        let interface = md.co_simulation.as_ref().or(md.model_exchange.as_ref());
        let identifier = interface.map_or(md.model_name.as_str(), |i| i.model_identifier.as_str());
        self.unpacked.binary(identifier)
    }
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
    /// per process (default: this program, if it called
    /// [`serve_workers_from_this_program`](crate::serve_workers_from_this_program));
    /// ignored for others. It is started with `TWOSTAGE_FMU_WORKER` set
    /// and must call that function first.
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
        let workers = self.workers.or_else(crate::worker::this_program);
        let engine = match workers {
            Some(command) if single => Engine::Workers(Box::new(WorkerPool::start(
                command,
                &self.setup,
                &loaded.unpacked.origin,
                &loaded.unpacked.root,
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

/// An FMU as a simulator: the parameters are set before initialization,
/// the inputs come from the input design and the noise inputs from the
/// experiment's stream, and the outputs are read at every sample.
///
/// Each worker thread gets its own instance (reset and reused between
/// experiments). An FMU that may be instantiated only once per process runs
/// in worker processes, one instance each, if a worker program is known
/// ([`serve_workers_from_this_program`](crate::serve_workers_from_this_program),
/// or the builder's), and otherwise one experiment at a time.
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

impl Simulator for FmuSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    /// Noise-free: the noise inputs held at zero; a given input replaces
    /// the input design.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            noiseless: true,
            given_input: true,
        }
    }

    fn shared_input(&self) -> Option<IoData> {
        self.input.as_ref()?.shared_record(&self.spec)
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        let spec = &self.spec;
        spec.prior().check(theta, spec.param_names(), true)?;
        let n = conditions.check_input(spec)?;
        out.resize(n, spec.input_names().len(), spec.output_names().len());
        // Every draw comes first, in a fixed order (each input whole, then
        // the noise inputs sample by sample), so that the FMU's run is a
        // function of the experiment's stream alone.
        match (conditions.input, &self.input) {
            (Some(given), _) => {
                for j in 0..spec.input_names().len() {
                    out.input_mut(j).copy_from_slice(given.input(j));
                }
            }
            (None, Some(input)) => {
                for j in 0..spec.input_names().len() {
                    input.fill(spec.sample_time(), rng, out.input_mut(j))?;
                }
            }
            (None, None) => {}
        }
        if conditions.noiseless {
            let noise = vec![0.0; n * self.noise_sd.len()];
            return self.run(theta, &noise, out);
        }
        let mut noise = Vec::with_capacity(n * self.noise_sd.len());
        for _ in 0..n {
            for &sd in &self.noise_sd {
                let e: f64 = StandardNormal.sample(rng);
                noise.push(sd * e);
            }
        }
        self.run(theta, &noise, out)
    }
}

impl FmuSimulator {
    /// Run the FMU on the record's inputs and `noise`; a non-finite output
    /// is the run's divergence.
    fn run(&self, theta: &[f64], noise: &[f64], out: &mut IoData) -> twostage_models::Result<()> {
        let spec = &self.spec;
        match &self.engine {
            Engine::InProcess(engine) => engine.run(&self.plan, theta, noise, out)?,
            Engine::Workers(pool) => pool.run(theta, noise, out)?,
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
