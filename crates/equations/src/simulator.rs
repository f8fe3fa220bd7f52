//! A model written as equations, as a [`Simulator`]: the input design
//! draws each experiment's inputs, the equations respond.

use twostage_models::InvalidSetting;
use twostage_models::{
    Block, BlockInputs, Capabilities, Conditions, ExperimentRng, InputSignal, IoData, ModelSpec,
    SimError, Simulator, simulate_one_by_one,
};

use crate::EquationModel;

/// Equations driven by an input design.
///
/// ```
/// use twostage_equations::{Equation, EquationModel, EquationSimulator, EquationsText, State, Time};
/// use twostage_models::{experiment_rng, ModelSpec, Prior, Simulator};
///
/// // Logistic growth x[k+1] = x[k] + r x[k] (1 - x[k]), observed as is.
/// let prior = Prior::uniform_box(&[0.1], &[0.5])?;
/// let spec = ModelSpec::new("logistic", &["r"], prior, 1.0, 30)?.with_signals(&[], &["x_obs"]);
/// let text = EquationsText {
///     time: Time::Discrete,
///     states: vec![State::new("x", "0.01", "x + r * x * (1 - x)")],
///     outputs: vec![Equation::new("x_obs", "x")],
///     ..EquationsText::default()
/// };
/// let simulator = EquationSimulator::new(spec.clone(), EquationModel::compile(&text, &spec)?, None);
/// let mut record = simulator.spec().new_record();
/// simulator.simulate(&[0.3], &mut experiment_rng(1, 0), &mut record)?;
/// assert!(record.output(0)[29] > 0.5 && record.output(0)[29] < 1.0);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct EquationSimulator {
    spec: ModelSpec,
    model: EquationModel,
    input: Option<InputSignal>,
}

impl EquationSimulator {
    /// The equations `model` of `spec`, its inputs drawn by `input` (each
    /// input in turn, from the experiment's stream); without a design, a
    /// model with inputs simulates only on a given input
    /// ([`Conditions::input`]: a measured record).
    pub fn new(spec: ModelSpec, model: EquationModel, input: Option<InputSignal>) -> Self {
        Self { spec, model, input }
    }
}

impl Simulator for EquationSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            noiseless: true,
            given_input: true,
        }
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        self.inputs_for(theta, rng, conditions, out)?;
        let noise = (!conditions.noiseless).then_some(rng);
        self.model.respond(theta, out, noise)
    }

    fn batch_size(&self) -> usize {
        BATCH
    }

    /// The compiled equations run the block together, unless each
    /// experiment has its own input.
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<(), SimError>> {
        if let BlockInputs::Each(_) = block.inputs {
            return simulate_one_by_one(self, thetas, rngs, block, outs);
        }
        let conditions = block.conditions(0);
        let ready: Vec<Result<(), SimError>> = thetas
            .iter()
            .zip(rngs.iter_mut())
            .zip(outs.iter_mut())
            .map(|((theta, rng), out)| self.inputs_for(theta, rng, conditions, out))
            .collect();
        if ready.iter().all(Result::is_ok) {
            let noises = (!conditions.noiseless).then_some(rngs);
            return self.model.respond_batch(thetas, outs, noises);
        }
        // Some could not start: the others one by one.
        ready
            .into_iter()
            .zip(thetas.iter().zip(rngs.iter_mut()).zip(outs.iter_mut()))
            .map(|(ready, ((theta, rng), out))| {
                ready?;
                let noise = (!conditions.noiseless).then_some(rng);
                self.model.respond(theta, out, noise)
            })
            .collect()
    }
}

/// Experiments a chart hands the equations at once: a few lanes' worth
/// ([`crate::model::LANES`]), so that records respond side by side.
const BATCH: usize = 4 * crate::model::LANES;

impl EquationSimulator {
    /// `out` shaped for the experiment and its inputs written: the given
    /// ones, or the design's drawn from `rng`; `theta` checked.
    fn inputs_for(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        // Length and finiteness, not the box: a simulator may be run
        // outside its prior on purpose (as the built-in models are).
        self.spec
            .prior()
            .check(theta, self.spec.param_names(), true)?;
        let n = conditions.check_input(&self.spec)?;
        let (n_u, n_y) = (
            self.spec.input_names().len(),
            self.spec.output_names().len(),
        );
        out.resize(n, n_u, n_y);
        match (conditions.input, &self.input) {
            (Some(given), _) => {
                for j in 0..n_u {
                    out.input_mut(j).copy_from_slice(given.input(j));
                }
            }
            (None, Some(design)) => {
                for j in 0..n_u {
                    design.fill(self.spec.sample_time(), rng, out.input_mut(j))?;
                }
            }
            (None, None) if n_u > 0 => {
                return Err(SimError::InvalidSetting(InvalidSetting {
                    name: "input",
                    value: self.spec.input_names().join(", "),
                    reason: "the equations' inputs need an input design ([input]: white, \
                             chicane or fixed) or a measured input"
                        .into(),
                }));
            }
            (None, None) => {}
        }
        Ok(())
    }
}
