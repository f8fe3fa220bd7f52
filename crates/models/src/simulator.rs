//! The `Simulator` trait: what the two-stage method needs of a model.

use crate::InvalidSetting;
use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::prior::Prior;
use crate::rng::ExperimentRng;

pub use crate::spec::{CarEquations, ModelSpec};

/// What a simulation is asked for besides theta and its random stream:
/// the model's response without noise, on a given input. The default is
/// an experiment as training simulates it (the model's noise, the
/// simulator's own input design).
///
/// ```
/// use twostage_models::{experiment_rng, Benchmark, Conditions, Simulator};
/// let model = Benchmark::new();
/// let mut measured = model.spec().new_record();
/// model.simulate(&[0.3], &mut experiment_rng(1, 0), &mut measured)?;
/// // The noise-free response of the same system to the measured input.
/// let mut response = model.spec().new_record();
/// let conditions = Conditions { noiseless: true, input: Some(&measured) };
/// model.simulate_under(&[0.3], &mut experiment_rng(2, 0), conditions, &mut response)?;
/// assert_eq!(response.input(0), measured.input(0));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct Conditions<'a> {
    /// No noise at all: neither process nor measurement noise, so the
    /// record is the model's own response (what an output-error fit
    /// compares a measured record with).
    pub noiseless: bool,
    /// Apply this record's inputs instead of the simulator's own input
    /// design (its outputs are not read).
    pub input: Option<&'a IoData>,
}

impl Conditions<'_> {
    /// An experiment as training simulates it.
    pub fn is_plain(&self) -> bool {
        !self.noiseless && self.input.is_none()
    }

    /// Check the given input (if any) against `spec` and say how many
    /// samples to simulate: the given record's, of any length (a
    /// validation record longer than the training records, say), else the
    /// model's. The record must hold the model's inputs, all finite.
    ///
    /// ```
    /// use twostage_models::{Benchmark, Conditions, IoData, Simulator};
    /// let model = Benchmark::new();
    /// let long = IoData::siso(&vec![0.5; 3000], &vec![0.0; 3000])?;
    /// let given = Conditions { noiseless: true, input: Some(&long) };
    /// assert_eq!(given.check_input(model.spec())?, 3000);
    /// assert_eq!(Conditions::default().check_input(model.spec())?, 1000);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidData`] naming the counts expected and given.
    pub fn check_input(&self, spec: &ModelSpec) -> Result<usize> {
        let Some(record) = self.input else {
            return Ok(spec.n_samples());
        };
        let n_u = spec.input_names().len();
        if record.n_samples() == 0 || record.n_inputs() != n_u {
            return Err(SimError::InvalidData(format!(
                "the given input has {} samples of {} signal(s); the model {} takes {n_u} \
                 ({}): give a record with those inputs",
                record.n_samples(),
                record.n_inputs(),
                spec.name(),
                spec.input_names().join(", ")
            )));
        }
        if let Some((j, k)) = (0..n_u).find_map(|j| {
            record
                .input(j)
                .iter()
                .position(|v| !v.is_finite())
                .map(|k| (j, k))
        }) {
            return Err(SimError::InvalidData(format!(
                "the given input {} is not a finite number at sample {k}",
                spec.input_names()[j]
            )));
        }
        Ok(record.n_samples())
    }
}

/// Which [`Conditions`] a simulator can honour.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// It can simulate without noise.
    pub noiseless: bool,
    /// It can apply a given input.
    pub given_input: bool,
}

impl Capabilities {
    /// Whether `conditions` can be honoured; the error says which part
    /// cannot and why it matters.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] naming the condition.
    pub fn check(&self, conditions: &Conditions<'_>, model: &str) -> Result<()> {
        if conditions.noiseless && !self.noiseless {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "noiseless",
                value: "true".into(),
                reason: format!(
                    "the simulator of {model} cannot simulate without its noise; a command \
                     source can when it speaks protocol 2: `protocol = 2` under [source], and \
                     its function takes the two keywords `noiseless` and `input` (with \
                     docs/protocol/twostage_protocol.py: `def simulate(theta, seed, index, \
                     noiseless=False, input=None)`, or `def batch(thetas, seeds, indices, \
                     noiseless=False, input=None)`; docs/protocol.md)"
                ),
            }));
        }
        if conditions.input.is_some() && !self.given_input {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "input",
                value: "a given record".into(),
                reason: format!(
                    "the simulator of {model} makes its own input and cannot apply a given \
                     one; a command source can when it speaks protocol 2: `protocol = 2` under \
                     [source], and its function takes the two keywords `noiseless` and `input` \
                     (with docs/protocol/twostage_protocol.py: `def simulate(theta, seed, \
                     index, noiseless=False, input=None)`; docs/protocol.md)"
                ),
            }));
        }
        Ok(())
    }
}

/// A simulator without its noise: every experiment runs under
/// `Conditions { noiseless: true, .. }`, for any source that can
/// ([`Capabilities::noiseless`]).
///
/// ```
/// use twostage_models::{experiment_rng, Benchmark, NoiseFree, Simulator};
/// let quiet = NoiseFree::new(Box::new(Benchmark::new()))?;
/// let (mut a, mut b) = (quiet.spec().new_record(), quiet.spec().new_record());
/// quiet.simulate(&[0.3], &mut experiment_rng(1, 0), &mut a)?;
/// // The same input (seed 1, experiment 0), with the noise: another output.
/// Benchmark::new().simulate(&[0.3], &mut experiment_rng(1, 0), &mut b)?;
/// assert_eq!(a.input(0), b.input(0));
/// assert_ne!(a.output(0), b.output(0));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
pub struct NoiseFree {
    inner: Box<dyn Simulator>,
    /// The inner model's spec, its noise said to be off.
    spec: ModelSpec,
}

impl NoiseFree {
    /// `inner` without its noise.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] when `inner` cannot simulate without
    /// noise (the message says what can).
    pub fn new(inner: Box<dyn Simulator>) -> Result<Self> {
        let conditions = Conditions {
            noiseless: true,
            input: None,
        };
        inner
            .capabilities()
            .check(&conditions, inner.spec().name())?;
        let spec = inner.spec().clone();
        let input_note = spec.input_note().to_string();
        let spec = spec.with_notes(&input_note, "none (run without the model's noise)");
        Ok(Self { inner, spec })
    }
}

impl Simulator for NoiseFree {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()> {
        let conditions = Conditions {
            noiseless: true,
            ..conditions
        };
        self.inner.simulate_one(theta, rng, conditions, out)
    }

    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        let block = Block {
            noiseless: true,
            ..block
        };
        self.inner.simulate_block(thetas, rngs, block, outs)
    }

    fn batch_size(&self) -> usize {
        self.inner.batch_size()
    }

    fn capabilities(&self) -> Capabilities {
        self.inner.capabilities()
    }

    fn shared_input(&self) -> Option<IoData> {
        self.inner.shared_input()
    }
}

/// Why a block of experiments on inputs of their own cannot run: inputs
/// of another count than the experiments', or an input for all given
/// beside them.
pub(crate) fn inputs_refused(
    experiments: usize,
    inputs: &[IoData],
    conditions: Conditions<'_>,
) -> Option<SimError> {
    if conditions.input.is_some() {
        return Some(SimError::InvalidData(
            "an input for every experiment and one per experiment: give the inputs per \
             experiment alone"
                .into(),
        ));
    }
    (inputs.len() != experiments).then(|| {
        SimError::InvalidData(format!(
            "{} inputs for {experiments} experiments: give one input per experiment",
            inputs.len()
        ))
    })
}

/// What a block of experiments runs under: the noise on or off, and
/// whose inputs: the simulator's own design, one record's for all, or a
/// record per experiment. [`Simulator::simulate_block`] receives one;
/// the default is a block as training simulates it.
///
/// ```
/// use twostage_models::{Block, BlockInputs, Conditions};
/// assert!(!Block::default().noiseless && matches!(Block::default().inputs, BlockInputs::Own));
/// let noiseless = Block::of(Conditions { noiseless: true, input: None });
/// assert!(noiseless.noiseless && matches!(noiseless.inputs, BlockInputs::Own));
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct Block<'a> {
    /// No noise at all ([`Conditions::noiseless`]).
    pub noiseless: bool,
    /// Whose inputs the experiments run on.
    pub inputs: BlockInputs<'a>,
}

/// Whose inputs a block of experiments runs on.
#[derive(Debug, Clone, Copy, Default)]
pub enum BlockInputs<'a> {
    /// Each experiment's own, from the simulator's input design.
    #[default]
    Own,
    /// This record's inputs, for every experiment.
    Shared(&'a IoData),
    /// Experiment `k` on the `k`-th record's inputs (as many records as
    /// experiments).
    Each(&'a [IoData]),
}

impl<'a> Block<'a> {
    /// A block whose every experiment runs under `conditions`.
    pub fn of(conditions: Conditions<'a>) -> Self {
        Self {
            noiseless: conditions.noiseless,
            inputs: conditions
                .input
                .map_or(BlockInputs::Own, BlockInputs::Shared),
        }
    }

    /// The conditions of the block's `k`-th experiment.
    pub fn conditions(&self, k: usize) -> Conditions<'a> {
        let input = match self.inputs {
            BlockInputs::Own => None,
            BlockInputs::Shared(record) => Some(record),
            BlockInputs::Each(records) => records.get(k),
        };
        Conditions {
            noiseless: self.noiseless,
            input,
        }
    }

    /// Why `capabilities` cannot run the block of `experiments`, if they
    /// cannot: a condition the simulator does not honour, or per-experiment
    /// inputs of another count than the experiments'.
    fn refusal(
        &self,
        experiments: usize,
        capabilities: Capabilities,
        model: &str,
    ) -> Option<SimError> {
        if let BlockInputs::Each(records) = self.inputs
            && records.len() != experiments
        {
            return Some(SimError::InvalidData(format!(
                "{} inputs for {experiments} experiments: give one input per experiment",
                records.len()
            )));
        }
        capabilities.check(&self.conditions(0), model).err()
    }
}

/// Every experiment of a block one by one through
/// [`Simulator::simulate_one`], each under its own conditions: what a
/// simulator that does not batch does with a block (the default of
/// [`Simulator::simulate_block`]), and what one that batches some
/// blocks does with the others.
pub fn simulate_one_by_one<S: Simulator + ?Sized>(
    simulator: &S,
    thetas: &[&[f64]],
    rngs: &mut [ExperimentRng],
    block: Block<'_>,
    outs: &mut [IoData],
) -> Vec<Result<()>> {
    thetas
        .iter()
        .zip(rngs.iter_mut())
        .zip(outs.iter_mut())
        .enumerate()
        .map(|(k, ((theta, rng), out))| {
            simulator.simulate_one(theta, rng, block.conditions(k), out)
        })
        .collect()
}

/// A block, once its conditions are checked against the simulator's
/// capabilities: the one place the batches' conditions are checked.
fn checked_block<S: Simulator + ?Sized>(
    simulator: &S,
    thetas: &[&[f64]],
    rngs: &mut [ExperimentRng],
    block: Block<'_>,
    outs: &mut [IoData],
) -> Vec<Result<()>> {
    let capabilities = simulator.capabilities();
    if let Some(e) = block.refusal(thetas.len(), capabilities, simulator.spec().name()) {
        return thetas.iter().map(|_| Err(e.clone())).collect();
    }
    simulator.simulate_block(thetas, rngs, block, outs)
}

/// A simulator of the system `P(theta)`: given a parameter vector and a
/// random stream, it produces one experiment's input/output record.
///
/// A simulator implements [`Simulator::spec`] and one way to simulate,
/// [`Simulator::simulate_one`]; it may say what else it can
/// ([`Simulator::capabilities`], [`Simulator::shared_input`]) and run
/// blocks in one go ([`Simulator::batch_size`],
/// [`Simulator::simulate_block`]). Callers use the provided methods
/// ([`Simulator::simulate`], [`Simulator::simulate_under`] and the
/// batches), which check the conditions against the capabilities once,
/// so an implementation is never asked what it did not offer; they are
/// not meant to be implemented.
///
/// Implementations must be deterministic given `(theta, rng)`, draw all their
/// randomness from `rng`, and return [`SimError::Diverged`]
/// instead of non-finite samples.
///
/// ```
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.3], &mut experiment_rng(1, 0), &mut record)?;
/// assert_eq!(record.n_samples(), 1000);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
pub trait Simulator: Send + Sync {
    /// What the model is: names, prior, sampling, signals.
    fn spec(&self) -> &ModelSpec;

    /// Simulate one experiment at `theta` under `conditions` into `out`,
    /// reshaping it to `spec().n_samples()` samples (or the given input's
    /// length). `conditions` ask only what [`Simulator::capabilities`]
    /// offers (a simulator that offers nothing gets plain ones).
    ///
    /// # Errors
    /// A parameter vector of the wrong length or with non-finite values, a
    /// given input of the wrong shape, or a simulation that diverges.
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()>;

    /// Which [`Conditions`] the simulator honours (default: none beyond a
    /// plain experiment).
    fn capabilities(&self) -> Capabilities {
        Capabilities::default()
    }

    /// The input every experiment gets, when the simulator's design gives
    /// all of them the same one (a fixed or deterministic signal): an
    /// estimator trained on its records learned that input, and a record
    /// with another is not one it can speak for. `None` when inputs vary
    /// (or the model has none).
    fn shared_input(&self) -> Option<IoData> {
        None
    }

    /// How many experiments the simulator would rather receive at once
    /// (default 1): charts hand it blocks of this size. A program that
    /// vectorizes (numpy over a batch) says more than 1.
    fn batch_size(&self) -> usize {
        1
    }

    /// Simulate a block of experiments: `thetas[k]` with the stream
    /// `rngs[k]` into `outs[k]` under `block`, one result each (`block`
    /// asks only what [`Simulator::capabilities`] offers). Each experiment
    /// must depend on its own parameter vector, stream and input only,
    /// never on the block it came in. Default:
    /// [`simulate_one_by_one`]; a command source sends the block in one
    /// request.
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        simulate_one_by_one(self, thetas, rngs, block, outs)
    }

    /// Simulate one experiment at `theta` into `out` as training does
    /// (provided).
    ///
    /// # Errors
    /// As [`Simulator::simulate_one`].
    fn simulate(&self, theta: &[f64], rng: &mut ExperimentRng, out: &mut IoData) -> Result<()> {
        self.simulate_one(theta, rng, Conditions::default(), out)
    }

    /// Simulate one experiment under `conditions` (noise-free, on a given
    /// input; provided).
    ///
    /// # Errors
    /// Conditions the simulator cannot honour
    /// ([`Capabilities::check`]), and those of
    /// [`Simulator::simulate_one`].
    fn simulate_under(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()> {
        self.capabilities().check(&conditions, self.spec().name())?;
        self.simulate_one(theta, rng, conditions, out)
    }

    /// A block of experiments as training simulates them, one result each
    /// (provided).
    fn simulate_batch(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        self.simulate_block(thetas, rngs, Block::default(), outs)
    }

    /// A block of experiments under the same `conditions`, one result
    /// each (provided).
    fn simulate_batch_under(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        conditions: Conditions<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        checked_block(self, thetas, rngs, Block::of(conditions), outs)
    }

    /// A block of experiments, each on its own given input: `thetas[k]`
    /// on `inputs[k]` with the stream `rngs[k]` into `outs[k]`, under
    /// `conditions` otherwise (without noise when `conditions.noiseless`;
    /// the inputs are these, so `conditions.input` must be `None`): an
    /// input design drawn per experiment by the caller, for a source that
    /// cannot draw it itself (provided).
    ///
    /// ```
    /// use twostage_models::{experiment_rng, Benchmark, Conditions, IoData, Simulator};
    /// let model = Benchmark::new();
    /// let inputs = [IoData::siso(&[0.5; 1000], &[0.0; 1000])?, IoData::siso(&[-1.0; 1000], &[0.0; 1000])?];
    /// let mut rngs = [experiment_rng(1, 0), experiment_rng(1, 1)];
    /// let mut outs = [model.spec().new_record(), model.spec().new_record()];
    /// let noiseless = Conditions { noiseless: true, input: None };
    /// let results = model.simulate_batch_on_inputs(&[&[0.3], &[0.3]], &mut rngs, &inputs, noiseless, &mut outs);
    /// assert!(results.iter().all(Result::is_ok));
    /// assert_eq!(outs[1].input(0), inputs[1].input(0));
    /// // One input for all beside one per experiment is refused.
    /// let both = Conditions { noiseless: true, input: Some(&inputs[0]) };
    /// let refused = model.simulate_batch_on_inputs(&[&[0.3], &[0.3]], &mut rngs, &inputs, both, &mut outs);
    /// assert!(refused.iter().all(Result::is_err));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    fn simulate_batch_on_inputs(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        inputs: &[IoData],
        conditions: Conditions<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        if let Some(e) = inputs_refused(thetas.len(), inputs, conditions) {
            return thetas.iter().map(|_| Err(e.clone())).collect();
        }
        let block = Block {
            noiseless: conditions.noiseless,
            inputs: BlockInputs::Each(inputs),
        };
        checked_block(self, thetas, rngs, block, outs)
    }

    /// The parameter names, in the order of theta (provided).
    fn param_names(&self) -> &[String] {
        self.spec().param_names()
    }

    /// The prior box (provided).
    fn prior(&self) -> &Prior {
        self.spec().prior()
    }
}

/// A simulator behind a reference, a box or an `Arc` is the simulator:
/// callers that own theirs (a `Box<dyn Simulator>` from a model file),
/// share one (an estimate's check, refinement and joint fit) or borrow one
/// share the generic code that takes `S: Simulator`.
macro_rules! forward_simulator {
    ($($pointer:ty),*) => {$(
        impl<S: Simulator + ?Sized> Simulator for $pointer {
            fn spec(&self) -> &ModelSpec {
                (**self).spec()
            }
            fn simulate_one(
                &self,
                theta: &[f64],
                rng: &mut ExperimentRng,
                conditions: Conditions<'_>,
                out: &mut IoData,
            ) -> Result<()> {
                (**self).simulate_one(theta, rng, conditions, out)
            }
            fn capabilities(&self) -> Capabilities {
                (**self).capabilities()
            }
            fn shared_input(&self) -> Option<IoData> {
                (**self).shared_input()
            }
            fn batch_size(&self) -> usize {
                (**self).batch_size()
            }
            fn simulate_block(
                &self,
                thetas: &[&[f64]],
                rngs: &mut [ExperimentRng],
                block: Block<'_>,
                outs: &mut [IoData],
            ) -> Vec<Result<()>> {
                (**self).simulate_block(thetas, rngs, block, outs)
            }
        }
    )*};
}

forward_simulator!(&S, Box<S>, std::sync::Arc<S>);

/// Check the length and finiteness of theta for `spec` (not the box:
/// simulators may be run outside their prior on purpose).
pub(crate) fn check_theta(spec: &ModelSpec, theta: &[f64]) -> Result<()> {
    spec.prior().check(theta, spec.param_names(), true)
}
