//! The simulators a model file makes: its source under the file's names and
//! noise, or none for a file that describes charts.

use twostage_models::{Capabilities, Conditions, ExperimentRng, IoData, ModelSpec, Simulator};

/// A model file's simulator: the source's, under the file's name, prior
/// and signal names, with the file's measurement noise added.
pub(super) struct FileSimulator {
    pub(super) inner: Box<dyn Simulator>,
    pub(super) spec: ModelSpec,
    pub(super) output_sd: Vec<f64>,
    /// Per output, the AR(1) coefficient of that noise (0: white).
    pub(super) output_ar: Vec<f64>,
    /// The input the file fixes for a source that is handed it (a command
    /// speaking protocol 2): every experiment gets it unless the caller
    /// gives another.
    pub(super) fixed_input: Option<IoData>,
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
        self.simulate_under(theta, rng, Conditions::default(), out)
    }

    fn capabilities(&self) -> Capabilities {
        self.inner.capabilities()
    }

    fn shared_input(&self) -> Option<IoData> {
        self.fixed_input
            .clone()
            .or_else(|| self.inner.shared_input())
    }

    fn simulate_under(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> twostage_models::Result<()> {
        let conditions = self.with_fixed_input(conditions);
        self.inner.simulate_under(theta, rng, conditions, out)?;
        self.measured(rng, conditions, out)
    }

    fn simulate_batch_under(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        conditions: Conditions<'_>,
        outs: &mut [IoData],
    ) -> Vec<twostage_models::Result<()>> {
        let conditions = self.with_fixed_input(conditions);
        let mut results = self
            .inner
            .simulate_batch_under(thetas, rngs, conditions, outs);
        for ((result, rng), out) in results.iter_mut().zip(rngs.iter_mut()).zip(outs.iter_mut()) {
            if result.is_ok() {
                *result = self.measured(rng, conditions, out);
            }
        }
        results
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
        self.simulate_batch_under(thetas, rngs, Conditions::default(), outs)
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
        if n != want || out.n_outputs() != self.output_sd.len() {
            return Err(twostage_models::SimError::InvalidData(format!(
                "the source gave {n} samples of {} outputs, the model file says {want} of {}",
                out.n_outputs(),
                self.output_sd.len()
            )));
        }
        if conditions.noiseless {
            return Ok(());
        }
        // After the source's own draws, from the same stream: experiment i
        // of seed s stays the same bits.
        // AR(1) of stationary sd `sd`: e_0 = sd z_0, e_k = a e_(k-1) + sd
        // sqrt(1 - a^2) z_k; white (a = 0) is the same bits as ever.
        for (j, (&sd, &a)) in self.output_sd.iter().zip(&self.output_ar).enumerate() {
            if sd > 0.0 {
                let innovation = sd * (1.0 - a * a).sqrt();
                let mut e = 0.0;
                for (k, y) in out.output_mut(j).iter_mut().enumerate() {
                    let z: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, rng);
                    e = if k == 0 {
                        sd * z
                    } else {
                        a * e + innovation * z
                    };
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
