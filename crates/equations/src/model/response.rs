//! A record's response: the states stepped from sample to sample by
//! the compiled programs, the outputs measured, the noise drawn; records
//! of a batch side by side (decision 047).

use rand_distr::{Distribution, StandardNormal};
use twostage_models::{ExperimentRng, InputSignal, IoData, SimError};

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
                values[slot] = InputSignal::sampled_value_at(at, self.sample_time, samples);
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

    /// `t` and the inputs there into the value table: linear between
    /// samples and held after the last (decision 005), or, held, those of
    /// the sample interval `k` being simulated.
    fn set_time_and_inputs(&self, values: &mut [f64], (t, k): (f64, usize), inputs: &[Vec<f64>]) {
        values[TIME_SLOT] = t;
        let start = self.names.inputs().start;
        for (j, samples) in inputs.iter().enumerate() {
            values[start + j] = match (self.input_path, self.time) {
                (InputPath::Linear, Time::Continuous { .. }) => {
                    twostage_models::InputSignal::sampled_value_at(t, self.sample_time, samples)
                }
                _ => samples[k.min(samples.len() - 1)],
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

/// Records of a batch that respond side by side (decision 047): one
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
mod tests {
    // A panic is how a test fails.
    #![allow(clippy::unwrap_used)]

    use std::cell::RefCell;

    use rand::RngExt;
    use twostage_models::{ModelSpec, OdeSystem, Prior, Rk4, experiment_rng};

    use super::*;
    use crate::{Equation, EquationsText, Integrator, State};

    /// Every function and operator, in the derivatives and the outputs.
    fn every_function() -> EquationModel {
        every_function_by(Integrator::Rk4, InputPath::Linear)
    }

    /// [`every_function`] integrated by `integrator`, its input on `path`.
    fn every_function_by(integrator: Integrator, path: InputPath) -> EquationModel {
        let prior = Prior::uniform_box(&[0.5, 0.1], &[2.0, 1.0]).unwrap();
        let spec = ModelSpec::new("all", &["k", "c"], prior, 0.05, 20)
            .unwrap()
            .with_signals(&["u"], &["y", "z"]);
        let text = EquationsText {
            time: Time::Continuous { substeps: 2 },
            states: vec![
                State::new("x", "k / 4", "v"),
                State::new(
                    "v",
                    "-c",
                    "(k * u - f - 4 * x) / (1 + c^2) + (x >= 1) - (x <= -1) + (v == 0) \
                     + (v != 0) * 0.01 + (x < v) - (x > v) + floor(x) + round(v) + ceil(x) \
                     + trunc(v) + fract(x) + asinh(x) + atan(v) + min(x, v) - max(v, x) \
                     + min(x, 0) + max(0, v) + abs(v) + sqrt(abs(x)) - -v",
                ),
            ],
            definitions: vec![
                Equation::new(
                    "f",
                    "c * sign(v) + 0.2 * v + sat(3 * x - u, 1.5) + signum(u)",
                ),
                Equation::new(
                    "g",
                    "if x < -0.5 then -1 else x > 0.5 then 1 else x^2 * 2 - x / 3",
                ),
            ],
            outputs: vec![
                Equation::new(
                    "y",
                    "x + g + atan2(x, 1 + v^2) + cos(t) * sin(t) + tanh(v) - exp(-(x^2)) \
                     + ln(2 + cosh(x)) + log10(3 + x^2) + cbrt(k * x) + PI * E",
                ),
                Equation::new(
                    "z",
                    "v + tan(x) + asin(x) + acos(v) + sinh(x) + acosh(x) + atanh(v) \
                     + log2(x) + log(v) + TAU",
                ),
            ],
            integrator,
            inputs: path,
            ..EquationsText::default()
        };
        EquationModel::compile(&text, &spec).unwrap()
    }

    /// Values that find the corners: zeros of both signs, infinities,
    /// NaN, the branches' marker, tiny and huge numbers, and ordinary
    /// ones.
    fn awkward(rng: &mut ExperimentRng) -> f64 {
        match rng.random_range(0..12) {
            0 => 0.0,
            1 => -0.0,
            2 => f64::INFINITY,
            3 => f64::NEG_INFINITY,
            4 => f64::NAN,
            5 => 1e-310,
            6 => -1e300,
            7 => rng.random_range(-1.0..1.0),
            8 => 1.0,
            9 => -1.0,
            _ => rng.random_range(-5.0..5.0),
        }
    }

    /// The model's derivatives for the models crate's integrator,
    /// interpreted on a table of their own, the inputs set at each stage
    /// time (or held at sample `k`'s).
    struct Reference<'a> {
        model: &'a EquationModel,
        derivatives: &'a Program,
        values: RefCell<Vec<f64>>,
        inputs: &'a [Vec<f64>],
        held: Option<usize>,
    }

    impl OdeSystem for Reference<'_> {
        fn dim(&self) -> usize {
            self.model.state_slots.len()
        }

        fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
            let mut values = self.values.borrow_mut();
            values[TIME_SLOT] = t;
            for (j, samples) in self.inputs.iter().enumerate() {
                values[self.model.names.inputs().start + j] = match self.held {
                    Some(k) => samples[k],
                    None => InputSignal::sampled_value_at(t, self.model.sample_time, samples),
                };
            }
            self.derivatives.interpret(&mut values, x, dx);
        }
    }

    /// NaN as one value: which NaN an operation passes on is the
    /// processor's choice, not the arithmetic's.
    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter()
            .map(|x| if x.is_nan() { u64::MAX } else { x.to_bits() })
            .collect()
    }

    /// The compiled steps (stages, inputs at the stage times, update; one
    /// a call, and a sample's two) give the bits of the models crate's
    /// Rk4, or of `x + h f`, around the interpreted derivatives, with
    /// linear and held inputs.
    #[test]
    fn compiled_steps_are_the_integrators_steps() {
        let mut rng = experiment_rng(11, 0);
        for integrator in [Integrator::Rk4, Integrator::Euler] {
            for path in [InputPath::Linear, InputPath::Hold] {
                let model = every_function_by(integrator, path);
                let Stepping::Integrated {
                    substeps,
                    steps,
                    one,
                    derivatives,
                } = &model.stepping
                else {
                    panic!("a continuous-time model without an integrator step");
                };
                // Both substeps of a sample in one call.
                assert_eq!(steps.starts.len(), 2);
                let h = model.sample_time / *substeps as f64;
                for (program, trial) in [one, steps].into_iter().cycle().zip(0..500) {
                    assert!(program.program.is_native());
                    let theta = [rng.random_range(0.5..2.0), rng.random_range(0.1..1.0)];
                    let mut table = model.record_table(&theta);
                    let x: Vec<f64> = (0..2).map(|_| rng.random_range(-1.5..1.5)).collect();
                    let inputs = vec![(0..20).map(|_| rng.random_range(-1.0..1.0)).collect()];
                    let k = rng.random_range(0..20);
                    let t_k = k as f64 * model.sample_time;
                    let first = match program.starts.len() {
                        1 => rng.random_range(0..*substeps),
                        _ => 0,
                    };
                    let t = |s: usize| t_k + s as f64 * h;
                    let mut reference = x.clone();
                    let system = Reference {
                        model: &model,
                        derivatives,
                        values: RefCell::new(table.clone()),
                        inputs: &inputs,
                        held: (path == InputPath::Hold).then_some(k),
                    };
                    for j in first..first + program.starts.len() {
                        match integrator {
                            Integrator::Rk4 => Rk4::new(2).step(&system, t(j), h, &mut reference),
                            Integrator::Euler => {
                                let mut dx = vec![0.0; 2];
                                system.rhs(t(j), &reference, &mut dx);
                                for (xi, d) in reference.iter_mut().zip(&dx) {
                                    *xi += h * d;
                                }
                            }
                        }
                    }
                    if program.stage_inputs.is_empty() {
                        model.set_time_and_inputs(&mut table, (t_k, k), &inputs);
                    }
                    for j in 0..program.starts.len() {
                        model.set_stage_times(program, j, &mut table, (t(first + j), h), &inputs);
                    }
                    let (mut compiled, mut interpreted) = (vec![0.0; 2], vec![0.0; 2]);
                    program.program.run_with(&mut table, &x, &mut compiled);
                    // The table as the step left it holds the stage
                    // inputs and the starts; the rest the program writes
                    // before it reads.
                    program.program.interpret(&mut table, &x, &mut interpreted);
                    assert_eq!(
                        bits(&compiled),
                        bits(&reference),
                        "{integrator:?}, {path:?}, trial {trial}: x {x:?} at t = {}",
                        t(first)
                    );
                    assert_eq!(bits(&interpreted), bits(&reference), "trial {trial}");
                }
            }
        }
    }

    /// Records of a batch respond side by side with the bits and the
    /// streams each has alone: with linear and held inputs, both
    /// integrators and discrete time, process and output noise.
    #[test]
    fn records_side_by_side_are_the_records_alone() {
        let prior = Prior::uniform_box(&[0.5, 0.1], &[2.0, 1.0]).unwrap();
        let spec = ModelSpec::new("lanes", &["k", "c"], prior, 0.05, 30)
            .unwrap()
            .with_signals(&["u"], &["y", "z"]);
        let mut rng = experiment_rng(5, 0);
        let variants = [
            (
                Time::Continuous { substeps: 3 },
                Integrator::Rk4,
                InputPath::Linear,
            ),
            (
                Time::Continuous { substeps: 2 },
                Integrator::Euler,
                InputPath::Hold,
            ),
            (
                Time::Continuous { substeps: 1 },
                Integrator::Rk4,
                InputPath::Hold,
            ),
            (Time::Discrete, Integrator::Rk4, InputPath::Hold),
        ];
        for (time, integrator, inputs) in variants {
            let mut text = EquationsText {
                time,
                integrator,
                inputs,
                states: vec![
                    State::new("x", "k / 4", "x + 0.05 * v"),
                    State::new(
                        "v",
                        "-c",
                        "v - 0.05 * (k * u - c * v * abs(v) - sqrt(abs(x)))",
                    ),
                ],
                outputs: vec![
                    Equation::new("y", "x + sin(t)"),
                    Equation::new("z", "v * v"),
                ],
                lognormal_sd: vec![0.0, 0.1],
                ..EquationsText::default()
            };
            text.states[1].noise_sd = 0.2;
            let model = EquationModel::compile(&text, &spec).unwrap();
            // Seven records: three pairs and one alone.
            let thetas: Vec<Vec<f64>> = (0..7)
                .map(|_| vec![rng.random_range(0.5..2.0), rng.random_range(0.1..1.0)])
                .collect();
            let theta_refs: Vec<&[f64]> = thetas.iter().map(Vec::as_slice).collect();
            let mut records: Vec<IoData> = (0..7)
                .map(|_| {
                    let mut r = IoData::zeros(30, 1, 2);
                    for u in r.input_mut(0) {
                        *u = rng.random_range(-1.0..1.0);
                    }
                    r
                })
                .collect();
            let mut alone = records.clone();
            let mut streams: Vec<ExperimentRng> = (0..7).map(|i| experiment_rng(9, i)).collect();
            let mut streams_alone = streams.clone();
            let results = model.respond_batch(&theta_refs, &mut records, Some(&mut streams));
            for i in 0..7 {
                model
                    .respond(&thetas[i], &mut alone[i], Some(&mut streams_alone[i]))
                    .unwrap();
                assert!(results[i].is_ok(), "{time:?}: record {i}");
                for j in 0..2 {
                    assert_eq!(
                        bits(records[i].output(j)),
                        bits(alone[i].output(j)),
                        "{time:?}, {integrator:?}, {inputs:?}: record {i}, output {j}"
                    );
                }
                let next = |r: &mut ExperimentRng| r.random_range(0..u64::MAX);
                assert_eq!(next(&mut streams[i]), next(&mut streams_alone[i]));
            }
        }
    }

    /// A record that fails in a batch fails as it does alone, and its
    /// partner responds as alone.
    #[test]
    fn a_record_failing_beside_another_fails_alone() {
        let prior = Prior::uniform_box(&[0.1], &[100.0]).unwrap();
        let spec = ModelSpec::new("blow-up", &["k"], prior, 0.1, 20)
            .unwrap()
            .with_signals(&[], &["y"]);
        // x' = k x^2 from 1 ends at t = 1 / k: within the record for k = 50.
        let text = EquationsText {
            states: vec![State::new("x", "1", "k * x * x")],
            outputs: vec![Equation::new("y", "x")],
            ..EquationsText::default()
        };
        let model = EquationModel::compile(&text, &spec).unwrap();
        let thetas: [&[f64]; 4] = [&[0.2], &[50.0], &[0.3], &[0.4]];
        let mut records = vec![IoData::zeros(20, 0, 1); 4];
        let results = model.respond_batch(&thetas, &mut records, None);
        for (i, theta) in thetas.iter().enumerate() {
            let mut alone = IoData::zeros(20, 0, 1);
            let result = model.respond(theta, &mut alone, None);
            match (&results[i], &result) {
                (Ok(()), Ok(())) => assert_eq!(bits(records[i].output(0)), bits(alone.output(0))),
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
                _ => panic!(
                    "record {i}: {:?} in the batch, {result:?} alone",
                    results[i]
                ),
            }
        }
        assert!(results[1].is_err() && results[0].is_ok());
        // Ten steps a call: the step that failed is found again, its
        // time the one where the models crate's Rk4 first leaves the
        // finite numbers.
        let Stepping::Integrated {
            steps, derivatives, ..
        } = &model.stepping
        else {
            panic!("a continuous-time model without an integrator step");
        };
        assert_eq!(steps.starts.len(), 10);
        let system = Reference {
            model: &model,
            derivatives,
            values: RefCell::new(model.record_table(&[50.0])),
            inputs: &[],
            held: None,
        };
        // The step's times as the model computes them: t_k + j h.
        let (mut x, h) = (vec![1.0], 0.1 / 10.0);
        let failed_at = (0..200)
            .map(|s| (s / 10) as f64 * 0.1 + (s % 10) as f64 * h)
            .find(|&t| {
                Rk4::new(1).step(&system, t, h, &mut x);
                !x[0].is_finite()
            })
            .map(|t| t + h);
        match &results[1] {
            Err(SimError::NonFiniteState { time, .. }) => assert_eq!(Some(*time), failed_at),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn compiled_code_gives_the_interpreters_bits() {
        let model = every_function();
        let Stepping::Integrated { derivatives, .. } = &model.stepping else {
            panic!("a continuous-time model without an integrator step");
        };
        let mut derivatives = derivatives.clone();
        derivatives.compile();
        assert!(derivatives.is_native() && model.measure_program.is_native());
        let mut rng = experiment_rng(7, 0);
        let n_states = model.state_slots.len();
        for trial in 0..2000 {
            let table: Vec<f64> = (0..model.table.values().len())
                .map(|_| awkward(&mut rng))
                .collect();
            let x: Vec<f64> = (0..n_states).map(|_| awkward(&mut rng)).collect();
            let (mut by_code, mut by_interpreter) = (table.clone(), table.clone());
            let (mut dx_code, mut dx_interpreter) = (vec![0.0; n_states], vec![0.0; n_states]);
            derivatives.run_with(&mut by_code, &x, &mut dx_code);
            derivatives.interpret(&mut by_interpreter, &x, &mut dx_interpreter);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&dx_code),
                bits(&dx_interpreter),
                "trial {trial}, x {x:?}"
            );
            // The interpreter also copies x into the table's state slots.
            scatter(&mut by_code, &model.state_slots, &x);
            assert_eq!(bits(&by_code), bits(&by_interpreter), "trial {trial}");
            model.measure_program.run(&mut by_code);
            model
                .measure_program
                .interpret(&mut by_interpreter, &[], &mut []);
            assert_eq!(bits(&by_code), bits(&by_interpreter), "trial {trial}");
        }
    }
}
