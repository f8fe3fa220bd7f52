//! The simulators a model file makes: its source under the file's names and
//! noise, or none for a file that describes charts.

use twostage_models::{
    Block, BlockInputs, Capabilities, Conditions, ExperimentRng, InputSignal, IoData, ModelSpec,
    Simulator,
};

/// A model file's simulator: the source's, under the file's name, prior
/// and signal names, with the file's measurement noise added.
pub(super) struct FileSimulator {
    pub(super) inner: Box<dyn Simulator>,
    pub(super) spec: ModelSpec,
    /// Per output, the noise the file adds (white of sd 0: none).
    pub(super) output_noise: Vec<twostage_models::ArNoise>,
    /// The input the file fixes for a source that is handed it (a command
    /// speaking protocol 2): every experiment gets it unless the caller
    /// gives another.
    pub(super) fixed_input: Option<IoData>,
    /// The design twostage draws each experiment's input from, for a
    /// source that is handed its input (a command speaking protocol 2):
    /// drawn from the experiment's stream before anything else.
    pub(super) design: Option<InputSignal>,
}

impl Simulator for FileSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn capabilities(&self) -> Capabilities {
        self.inner.capabilities()
    }

    fn shared_input(&self) -> Option<IoData> {
        if let Some(design) = &self.design {
            return design.shared_record(&self.spec);
        }
        self.fixed_input
            .clone()
            .or_else(|| self.inner.shared_input())
    }

    fn batch_size(&self) -> usize {
        self.inner.batch_size()
    }

    /// One experiment as a block of one.
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        self.simulate_block(
            &[theta],
            std::slice::from_mut(rng),
            Block::of(conditions),
            std::slice::from_mut(out),
        )
        .pop()
        .unwrap_or_else(|| {
            Err(twostage_models::SimError::InvalidData(
                "the source answered no record".into(),
            ))
        })
    }

    /// The source's block on the file's inputs (its design's, drawn per
    /// experiment, or its fixed input), then the file's measurement.
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<twostage_models::Result<()>> {
        let drawn;
        let block = match (&self.design, block.inputs) {
            (Some(design), BlockInputs::Own) => {
                drawn = match self.drawn_inputs(design, rngs) {
                    Ok(inputs) => inputs,
                    Err(e) => return thetas.iter().map(|_| Err(e.clone())).collect(),
                };
                Block {
                    inputs: BlockInputs::Each(&drawn),
                    ..block
                }
            }
            (_, BlockInputs::Each(_)) => block,
            _ => Block::of(self.with_fixed_input(block.conditions(0))),
        };
        // The source's own entry points check what the file asks of it.
        let mut results = match block.inputs {
            BlockInputs::Each(inputs) => {
                let noise = Conditions {
                    noiseless: block.noiseless,
                    input: None,
                };
                self.inner
                    .simulate_batch_on_inputs(thetas, rngs, inputs, noise, outs)
            }
            _ => self
                .inner
                .simulate_batch_under(thetas, rngs, block.conditions(0), outs),
        };
        for (k, ((result, rng), out)) in results
            .iter_mut()
            .zip(rngs.iter_mut())
            .zip(outs.iter_mut())
            .enumerate()
        {
            if result.is_ok() {
                *result = self.measured(rng, block.conditions(k), out);
            }
        }
        results
    }
}

impl FileSimulator {
    /// The caller's conditions, with the file's fixed input where the
    /// caller gives none.
    fn with_fixed_input<'c>(&'c self, conditions: Conditions<'c>) -> Conditions<'c> {
        match (&conditions.input, &self.fixed_input) {
            (None, Some(fixed)) => Conditions {
                input: Some(fixed),
                ..conditions
            },
            _ => conditions,
        }
    }

    /// Each experiment's input drawn from `design`, from its own stream:
    /// the same bits as a source that draws the design itself.
    fn drawn_inputs(
        &self,
        design: &InputSignal,
        rngs: &mut [ExperimentRng],
    ) -> twostage_models::Result<Vec<IoData>> {
        rngs.iter_mut()
            .map(|rng| {
                let mut record = self.spec.new_record();
                for j in 0..record.n_inputs() {
                    design.fill(self.spec.sample_time(), rng, record.input_mut(j))?;
                }
                Ok(record)
            })
            .collect()
    }

    /// Check the source's record against the file and add the file's
    /// measurement noise (none for a noise-free run).
    fn measured(
        &self,
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        let n = out.n_samples();
        // A given record sets the length; otherwise the file's.
        let want = conditions
            .input
            .map_or(self.spec.n_samples(), IoData::n_samples);
        if n != want || out.n_outputs() != self.output_noise.len() {
            return Err(twostage_models::SimError::InvalidData(format!(
                "the source gave {n} samples of {} outputs, the model file says {want} of {}",
                out.n_outputs(),
                self.output_noise.len()
            )));
        }
        if conditions.noiseless {
            return Ok(());
        }
        // After the source's own draws, from the same stream: experiment i
        // of seed s stays the same bits.
        // White noise is `sd z` to the bit, as ever; AR(1) starts
        // stationary; a residual's AR model after a burn-in.
        let mut path = Vec::new();
        for (j, noise) in self.output_noise.iter().enumerate() {
            if noise.variance() > 0.0 {
                path.resize(n, 0.0);
                noise.fill(rng, &mut path);
                for (y, e) in out.output_mut(j).iter_mut().zip(&path) {
                    *y += e;
                }
            }
        }
        Ok(())
    }
}

/// The model of a file without a source: a spec, and a refusal to simulate.
pub(super) struct ChartsOnly {
    pub(super) spec: ModelSpec,
    pub(super) origin: String,
}

impl Simulator for ChartsOnly {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate_one(
        &self,
        _: &[f64],
        _: &mut ExperimentRng,
        _: Conditions<'_>,
        _: &mut IoData,
    ) -> twostage_models::Result<()> {
        Err(twostage_models::SimError::InvalidData(format!(
            "{} has no [source]: its charts come from files, it cannot simulate",
            self.origin
        )))
    }
}
