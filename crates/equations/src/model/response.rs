//! A record's response: the states stepped from sample to sample by
//! the compiled programs, the outputs measured, the noise drawn; records
//! of a batch side by side.

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{ExperimentRng, IoData, SimError};

use super::EquationModel;
use crate::expression::Program;
use crate::integrator::IntegratorStep;
use crate::ops::lacks_branch;
use crate::{InputPath, Measure, TIME_SLOT, Time};

impl EquationModel {
    /// The response to the inputs already in `record` (one per model
    /// input, of any length) at `theta`, written into its outputs; with
    /// `noise`, the process and multiplicative output noise drawn from it
    /// (process noise at each step in state order, then the outputs'
    /// noise at each sample), else none.
    ///
    /// # Errors
    /// [`SimError::NonFiniteState`] naming the state and time where a
    /// state became NaN or infinite; [`SimError::InvalidData`] where a
    /// piecewise value had no branch that applied.
    pub fn respond(
        &self,
        theta: &[f64],
        record: &mut IoData,
        noise: Option<&mut ExperimentRng>,
    ) -> Result<(), SimError> {
        let noise = noise.map(std::slice::from_mut);
        self.respond_lanes(
            &self.stepping,
            &[theta],
            std::slice::from_mut(record),
            noise,
        )
    }

    /// [`EquationModel::respond`] for each of `records` at `thetas[k]`,
    /// with noise from `noises[k]` (or none): records of a length
    /// respond [`LANES`] at a time through one compiled step, each the
    /// bits it has alone (its own table, state and stream); where one of
    /// them fails, they respond again one by one from their streams as
    /// they were, so that each failure is its own.
    pub(crate) fn respond_batch(
        &self,
        thetas: &[&[f64]],
        records: &mut [IoData],
        mut noises: Option<&mut [ExperimentRng]>,
    ) -> Vec<Result<(), SimError>> {
        let mut results = Vec::with_capacity(records.len());
        let mut start = 0;
        while start < records.len() {
            let end = (start + LANES).min(records.len());
            let length = records[start].n_samples();
            let side_by_side =
                end - start == LANES && records[start..end].iter().all(|r| r.n_samples() == length);
            if side_by_side {
                let streams = noises.as_deref_mut().map(|r| &mut r[start..end]);
                let kept: Option<Vec<ExperimentRng>> = streams.as_deref().map(<[_]>::to_vec);
                let together = self.respond_lanes(
                    &self.wide,
                    &thetas[start..end],
                    &mut records[start..end],
                    streams,
                );
                if together.is_ok() {
                    results.extend((start..end).map(|_| Ok(())));
                    start = end;
                    continue;
                }
                if let (Some(streams), Some(kept)) = (noises.as_deref_mut(), kept) {
                    streams[start..end].clone_from_slice(&kept);
                }
            }
            for k in start..end {
                let noise = noises.as_deref_mut().map(|r| &mut r[k]);
                results.push(self.respond(thetas[k], &mut records[k], noise));
            }
            start = end;
        }
        results
    }

    /// The response of `records` side by side, one lane each, stepped by
    /// `stepping` (compiled for that many lanes); the first failure ends
    /// them all.
    fn respond_lanes(
        &self,
        stepping: &Stepping,
        thetas: &[&[f64]],
        records: &mut [IoData],
        mut noises: Option<&mut [ExperimentRng]>,
    ) -> Result<(), SimError> {
        let Some(n) = records.first().map(IoData::n_samples) else {
            return Ok(());
        };
        let (stride, n_states) = (self.table.len(), self.state_slots.len());
        let mut values = Vec::with_capacity(thetas.len() * stride);
        for theta in thetas {
            values.extend(self.record_table(theta));
        }
        let mut x = vec![0.0; thetas.len() * n_states];
        let first_state = self.names.states().start;
        let lanes = thetas.len();
        for ((table, x), theta) in values
            .chunks_mut(stride)
            .zip(per_lane(&mut x, n_states, lanes))
            .zip(thetas)
        {
            for (i, expression) in self.initial.iter().enumerate() {
                x[i] = expression.eval(table);
                table[first_state + i] = x[i];
            }
            self.check_states(x, 0.0, theta)?;
        }
        let inputs: Vec<Vec<Vec<f64>>> = records
            .iter()
            .map(|r| (0..r.n_inputs()).map(|j| r.input(j).to_vec()).collect())
            .collect();
        let mut y = vec![vec![vec![0.0; n]; self.outputs.len()]; records.len()];
        let t_step = self.sample_time;
        let mut next = vec![0.0; x.len()];
        // Each lane's table, state, inputs and outputs.
        macro_rules! lanes {
            () => {
                values
                    .chunks_mut(stride)
                    .zip(per_lane(&mut x, n_states, lanes))
                    .zip(inputs.iter().zip(y.iter_mut()))
                    .map(|((table, x), (inputs, y))| (table, x, inputs, y))
            };
        }
        for k in 0..n {
            let t_k = k as f64 * t_step;
            if self.measure == Measure::Start {
                for (table, x, inputs, y) in lanes!() {
                    self.measure_outputs(table, (t_k, k, x), inputs, (y, k))?;
                }
            }
            match stepping {
                Stepping::Integrated {
                    substeps,
                    steps,
                    one,
                    ..
                } => {
                    let h = t_step / *substeps as f64;
                    if steps.stage_inputs.is_empty() {
                        // Held through the sample (or none): set once.
                        for (table, _, inputs, _) in lanes!() {
                            self.set_time_and_inputs(table, (t_k, k), inputs);
                        }
                    }
                    let per_call = steps.starts.len();
                    for first in (0..*substeps).step_by(per_call) {
                        let t = |s: usize| t_k + s as f64 * h;
                        for (table, _, inputs, _) in lanes!() {
                            for j in 0..per_call {
                                self.set_stage_times(steps, j, table, (t(first + j), h), inputs);
                            }
                        }
                        steps.program.run_with(&mut values, &x, &mut next);
                        if per_call == 1 {
                            std::mem::swap(&mut x, &mut next);
                            let (t, scale) = (t(first) + h, h.sqrt());
                            self.after_step(&mut x, noises.as_deref_mut(), (t, scale), thetas)?;
                            continue;
                        }
                        // Several steps a call (no process noise): a state
                        // that became NaN or infinite stays so, and its
                        // step is found again one step at a time.
                        if next.iter().all(|v| v.is_finite()) {
                            std::mem::swap(&mut x, &mut next);
                            continue;
                        }
                        for j in first..first + per_call {
                            for (table, _, inputs, _) in lanes!() {
                                self.set_stage_times(one, 0, table, (t(j), h), inputs);
                            }
                            one.program.run_with(&mut values, &x, &mut next);
                            std::mem::swap(&mut x, &mut next);
                            self.after_step(&mut x, None, (t(j) + h, 1.0), thetas)?;
                        }
                    }
                }
                Stepping::Discrete { next: program } => {
                    // Measured at the start, the table holds this
                    // sample's time, inputs and states already.
                    if self.measure != Measure::Start {
                        for (table, _, inputs, _) in lanes!() {
                            self.set_time_and_inputs(table, (t_k, k), inputs);
                        }
                    }
                    program.run_with(&mut values, &x, &mut next);
                    std::mem::swap(&mut x, &mut next);
                    self.after_step(&mut x, noises.as_deref_mut(), (t_k + t_step, 1.0), thetas)?;
                }
            }
            if self.measure == Measure::End {
                let (t, at) = (t_k + t_step, (k + 1).min(n - 1));
                for (table, x, inputs, y) in lanes!() {
                    self.measure_outputs(table, (t, at, x), inputs, (y, k))?;
                }
            }
            if let Some(streams) = noises.as_deref_mut() {
                for (y, rng) in y.iter_mut().zip(streams.iter_mut()) {
                    for &(j, sd) in &self.lognormal {
                        let z: f64 = StandardNormal.sample(rng);
                        y[j][k] *= (sd * z).exp();
                    }
                }
            }
        }
        for (record, y) in records.iter_mut().zip(&y) {
            for (j, column) in y.iter().enumerate() {
                record.output_mut(j).copy_from_slice(column);
            }
        }
        Ok(())
    }

    /// After a step to time `t`: each lane's process noise (its sd times
    /// `scale`) from its stream, then its states checked.
    fn after_step(
        &self,
        x: &mut [f64],
        mut noises: Option<&mut [ExperimentRng]>,
        (t, scale): (f64, f64),
        thetas: &[&[f64]],
    ) -> Result<(), SimError> {
        let n_states = self.state_slots.len();
        for (lane, (x, theta)) in per_lane(x, n_states, thetas.len()).zip(thetas).enumerate() {
            if let Some(rng) = noises.as_deref_mut().and_then(|r| r.get_mut(lane)) {
                self.add_process_noise(x, rng, scale);
            }
            self.check_states(x, t, theta)?;
        }
        Ok(())
    }

    /// The value table of a record at `theta`: its numbers, the
    /// parameters, and what is computed once a record.
    fn record_table(&self, theta: &[f64]) -> Vec<f64> {
        let mut values = self.table.values();
        values[self.names.parameters()].copy_from_slice(theta);
        let first = self.names.defined().start;
        for &i in &self.constant_order {
            self.defined[i].prepare(&mut values);
            values[first + i] = self.defined[i].eval(&mut values);
        }
        for expression in self.updates.iter().chain(&self.defined) {
            expression.prepare(&mut values);
        }
        values
    }

    /// A lane's table before step `j` of a call of `steps`, from `t` and
    /// of length `h`: its start, and the inputs at its stage times (unless
    /// held).
    fn set_stage_times(
        &self,
        steps: &IntegratorStep,
        j: usize,
        values: &mut [f64],
        (t, h): (f64, f64),
        inputs: &[Vec<f64>],
    ) {
        values[steps.starts[j]] = t;
        let Some(stage_inputs) = steps.stage_inputs.get(j) else {
            return;
        };
        // The stage times as the models crate's Rk4 computes them: t,
        // t + h / 2, t + h.
        let times = [t, t + 0.5 * h, t + h];
        for (slots, &at) in stage_inputs.iter().zip(&times) {
            for (&slot, samples) in slots.iter().zip(inputs) {
                values[slot] = self.input_path.value_at(at, self.sample_time, samples);
            }
        }
    }

    /// Each noisy state's process noise over a step: its sd times `scale`
    /// (the square root of a continuous step's length, 1 in discrete
    /// time) times a standard normal draw, in state order.
    fn add_process_noise(&self, x: &mut [f64], rng: &mut ExperimentRng, scale: f64) {
        for &(i, sd) in &self.process_noise {
            let z: f64 = StandardNormal.sample(rng);
            x[i] += sd * scale * z;
        }
    }

    /// The outputs at time `t` (of input sample `at`) and states `x` into
    /// sample `k` of `y`.
    fn measure_outputs(
        &self,
        values: &mut [f64],
        (t, at, x): (f64, usize, &[f64]),
        inputs: &[Vec<f64>],
        (y, k): (&mut [Vec<f64>], usize),
    ) -> Result<(), SimError> {
        self.set_time_and_inputs(values, (t, at), inputs);
        scatter(values, &self.state_slots, x);
        let first = self.names.defined().start;
        self.measure_program.run(values);
        for (j, &i) in self.outputs.iter().enumerate() {
            let v = values[first + i];
            if lacks_branch(v) {
                return Err(SimError::InvalidData(format!(
                    "the output {} has no branch that applies at t = {t}: end its `if ... then \
                     ...` with `else ...`",
                    self.names.name(first + i)
                )));
            }
            y[j][k] = v;
        }
        Ok(())
    }

    /// `t` and the inputs there into the value table: read between
    /// samples as the model's input path says and held after the last,
    /// or, held, those of the sample interval `k` being simulated.
    fn set_time_and_inputs(&self, values: &mut [f64], (t, k): (f64, usize), inputs: &[Vec<f64>]) {
        values[TIME_SLOT] = t;
        let start = self.names.inputs().start;
        for (j, samples) in inputs.iter().enumerate() {
            values[start + j] = match (self.input_path, self.time) {
                (InputPath::Hold, _) | (_, Time::Discrete) => samples[k.min(samples.len() - 1)],
                (path, Time::Continuous { .. }) => path.value_at(t, self.sample_time, samples),
            };
        }
    }

    fn check_states(&self, x: &[f64], time: f64, theta: &[f64]) -> Result<(), SimError> {
        match x.iter().position(|v| !v.is_finite() || lacks_branch(*v)) {
            None => Ok(()),
            Some(i) => Err(SimError::NonFiniteState {
                state: self.names.name(self.names.states().start + i).to_string(),
                value: x[i],
                time,
                theta: theta.to_vec(),
            }),
        }
    }
}

/// Records of a batch that respond side by side: one
/// record's step is a chain of dependent operations, and a second chain
/// beside it fills the processor's idle time.
pub(crate) const LANES: usize = 2;

/// How a model's states move from one sample to the next.
#[derive(Debug, Clone)]
pub(super) enum Stepping {
    /// Continuous time: `substeps` integrator steps a sample, `steps` of
    /// them a call of compiled code (all of them where the program stays
    /// short and no process noise comes between); `one` takes one, to
    /// find the step where a state failed.
    Integrated {
        substeps: usize,
        steps: Box<IntegratorStep>,
        one: Box<IntegratorStep>,
        /// The derivatives alone: what the tests integrate by the models
        /// crate's own Rk4 to check the compiled step against.
        #[cfg(test)]
        derivatives: Program,
    },
    /// Discrete time: the next states, one program a sample.
    Discrete { next: Program },
}

impl Stepping {
    /// The same stepping for `lanes` records side by side, their tables
    /// `stride` slots long laid end to end ([`Program::lanes`]); each
    /// lane's slots are the first's, `stride` further on a lane.
    pub(super) fn lanes(&self, lanes: usize, stride: usize) -> Self {
        let widen = |program: &Program| {
            let mut wide = program.lanes(lanes, stride);
            wide.compile();
            wide
        };
        match self {
            Self::Integrated {
                substeps,
                steps,
                one,
                #[cfg(test)]
                derivatives,
            } => Self::Integrated {
                substeps: *substeps,
                steps: Box::new(IntegratorStep {
                    program: widen(&steps.program),
                    ..(**steps).clone()
                }),
                one: Box::new(IntegratorStep {
                    program: widen(&one.program),
                    ..(**one).clone()
                }),
                #[cfg(test)]
                derivatives: derivatives.clone(),
            },
            Self::Discrete { next } => Self::Discrete { next: widen(next) },
        }
    }
}

// The states move into the value table through a list of slots rather
// than `copy_from_slice`: a model has a few states, and the call of
// `memmove` that a copy of a range becomes (even written as a loop) cost
// more than the equations between (perf on the tanks model: 16% of its
// time).

/// The `lanes` states of `n` values each in `x`, one after the other (a
/// model may have no states: then as many empty ones).
fn per_lane(x: &mut [f64], n: usize, lanes: usize) -> impl Iterator<Item = &mut [f64]> {
    x.chunks_mut(n.max(1))
        .chain(std::iter::repeat_with(<&mut [f64]>::default))
        .take(lanes)
}

/// `x` into the table's `slots`.
#[inline]
fn scatter(values: &mut [f64], slots: &[usize], x: &[f64]) {
    for (&slot, &v) in slots.iter().zip(x) {
        values[slot] = v;
    }
}

#[cfg(test)]
mod tests;
