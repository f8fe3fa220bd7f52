//! A model's equations compiled: the value table's layout, each right
//! side's slots, the order in which the defined quantities are evaluated,
//! and a record's response.

use std::cell::{Cell, RefCell};

use exmex::MakeOperators;
use rand_distr::{Distribution, StandardNormal};
use twostage_models::{ExperimentRng, IoData, ModelSpec, OdeSystem, Rk4, SimError};

use crate::expression::{Expression, Program, Table};
use crate::ops::{EquationOps, lacks_branch};
use crate::{EquationError, EquationsText, InputPath, Integrator, Measure, Names, TIME_SLOT, Time};

/// Equations compiled for one model: see the crate's example.
#[derive(Debug, Clone)]
pub struct EquationModel {
    names: Names,
    /// The value table's slots beyond the names: numbers and the
    /// instructions' results.
    table: Table,
    time: Time,
    measure: Measure,
    integrator: Integrator,
    input_path: InputPath,
    sample_time: f64,
    initial: Vec<Expression>,
    updates: Vec<Expression>,
    /// The states with process noise and its sd, in state order.
    process_noise: Vec<(usize, f64)>,
    /// Every defined quantity (intermediates, then outputs), by slot.
    defined: Vec<Expression>,
    /// Those that read only parameters (directly or through others like
    /// them), in order: evaluated once per record.
    constant_order: Vec<usize>,
    /// At every step: the others the updates need, in order, then the
    /// updates (the states read from the integrator's vector, the
    /// derivatives or next states given back in another).
    step_program: Program,
    /// The states' slots in the table.
    state_slots: Vec<usize>,
    /// At every sample: the others the outputs need, in order, then the
    /// outputs, each into its slot.
    measure_program: Program,
    /// The outputs' indices in `defined`, in the model's output order.
    outputs: Vec<usize>,
    /// The outputs with log-normal noise and its sd, in output order.
    lognormal: Vec<(usize, f64)>,
}

impl EquationModel {
    /// Compile `text` for the model `spec` (its parameters, inputs,
    /// outputs and sample time).
    ///
    /// # Errors
    /// An [`EquationError`] naming the equation: a syntax error (with its
    /// position), an unknown name (with the known ones), a name defined
    /// twice, an output missing or not the model's, an initial value that
    /// reads a state before it is defined, a cycle among the defined
    /// quantities, or a setting out of range.
    pub fn compile(text: &EquationsText, spec: &ModelSpec) -> Result<Self, EquationError> {
        let fail = |equation: &str, message: String| EquationError {
            equation: equation.to_string(),
            position: None,
            message,
        };
        if let Time::Continuous { substeps: 0 } = text.time {
            return Err(fail("substeps", "must be at least 1".into()));
        }
        if text.states.is_empty() && text.outputs.is_empty() {
            return Err(fail(
                "equations",
                "there are no states and no outputs".into(),
            ));
        }
        let states: Vec<String> = text.states.iter().map(|s| s.name.clone()).collect();
        let defined: Vec<String> = text
            .definitions
            .iter()
            .chain(&text.outputs)
            .map(|e| e.name.clone())
            .collect();
        check_names(spec, &states, &defined)?;
        let outputs = output_indices(text, spec)?;
        let names = Names::new(spec.param_names(), spec.input_names(), &states, &defined);
        let mut table = Table::new(names.len());
        let mut initial = Vec::with_capacity(states.len());
        for (i, state) in text.states.iter().enumerate() {
            let later = names.states().start + i;
            let allowed = |slot: usize| {
                let earlier_state = names.states().contains(&slot) && slot < later;
                if names.parameters().contains(&slot) || slot == TIME_SLOT || earlier_state {
                    Ok(())
                } else if names.states().contains(&slot) {
                    Err(format!(
                        "uses the state `{}` before it is defined: an initial value may use the \
                         parameters and the states listed before it",
                        names.name(slot)
                    ))
                } else {
                    Err(format!(
                        "uses `{}`: an initial value may use the parameters and the states \
                         listed before it",
                        names.name(slot)
                    ))
                }
            };
            initial.push(Expression::compile(
                &format!("{}.initial", state.name),
                &state.initial,
                &names,
                allowed,
                &mut table,
            )?);
        }
        let update_key = match text.time {
            Time::Continuous { .. } => "derivative",
            Time::Discrete => "next",
        };
        let mut updates = text
            .states
            .iter()
            .map(|s| {
                Expression::compile(
                    &format!("{}.{update_key}", s.name),
                    &s.update,
                    &names,
                    |_| Ok(()),
                    &mut table,
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        for s in &text.states {
            if !(s.noise_sd.is_finite() && s.noise_sd >= 0.0) {
                return Err(fail(
                    &format!("{}.noise", s.name),
                    format!("must be finite and >= 0, not {}", s.noise_sd),
                ));
            }
        }
        let mut defined_expressions = text
            .definitions
            .iter()
            .chain(&text.outputs)
            .map(|e| Expression::compile(&e.name, &e.text, &names, |_| Ok(()), &mut table))
            .collect::<Result<Vec<_>, _>>()?;
        let first = names.defined().start;
        let order = evaluation_order(&defined_expressions, first, &defined)?;
        let constant = per_record(&order, &defined_expressions, &names);
        let varying = |needed: Vec<bool>| -> Vec<usize> {
            order
                .iter()
                .copied()
                .filter(|&i| needed[i] && !constant[i])
                .collect()
        };
        let update_reads: Vec<usize> = updates.iter().flat_map(|u| u.reads().to_vec()).collect();
        let update_order = varying(needed_by(&update_reads, &defined_expressions, first));
        let output_reads: Vec<usize> = outputs.iter().map(|&i| first + i).collect();
        let output_order = varying(needed_by(&output_reads, &defined_expressions, first));
        let constant_order = order.iter().copied().filter(|&i| constant[i]).collect();
        // What reads only parameters and per-record quantities is
        // computed once a record, not at every step.
        let fixed = |slot: usize| {
            names.parameters().contains(&slot)
                || (slot >= first && slot < names.len() && constant[slot - first])
        };
        for expression in updates.iter_mut().chain(&mut defined_expressions) {
            expression.hoist(names.len(), fixed);
        }
        let state_slots: Vec<usize> = names.states().collect();
        let update_slots: Vec<usize> = (0..updates.len()).map(|_| table.fresh()).collect();
        let mut step = Program::with_vectors(&state_slots, &update_slots);
        for &i in &update_order {
            defined_expressions[i].append_to(&mut step, first + i);
        }
        for (update, &slot) in updates.iter().zip(&update_slots) {
            update.append_to(&mut step, slot);
        }
        step.compile();
        let mut measure = Program::default();
        for &i in &output_order {
            defined_expressions[i].append_to(&mut measure, first + i);
        }
        measure.compile();
        let mut lognormal_sd = text.lognormal_sd.clone();
        lognormal_sd.resize(spec.output_names().len(), 0.0);
        if let Some((j, sd)) = lognormal_sd
            .iter()
            .enumerate()
            .find(|(_, sd)| !(sd.is_finite() && **sd >= 0.0))
        {
            return Err(fail(
                &format!("{}.lognormal", spec.output_names()[j]),
                format!("must be finite and >= 0, not {sd}"),
            ));
        }
        Ok(Self {
            names,
            table,
            time: text.time,
            measure: text.measure,
            integrator: text.integrator,
            input_path: text.inputs,
            sample_time: spec.sample_time(),
            initial,
            updates,
            process_noise: noisy(text.states.iter().map(|s| s.noise_sd)),
            defined: defined_expressions,
            constant_order,
            step_program: step,
            state_slots,
            measure_program: measure,
            outputs,
            lognormal: noisy(lognormal_sd),
        })
    }

    /// Whether the equations draw noise of their own (process noise or
    /// multiplicative output noise).
    pub fn is_noisy(&self) -> bool {
        !(self.process_noise.is_empty() && self.lognormal.is_empty())
    }

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
        mut noise: Option<&mut ExperimentRng>,
    ) -> Result<(), SimError> {
        let n = record.n_samples();
        let n_outputs = self.outputs.len();
        let mut values = self.table.values();
        let parameters = self.names.parameters();
        values[parameters.clone()].copy_from_slice(theta);
        let first = self.names.defined().start;
        for &i in &self.constant_order {
            self.defined[i].prepare(&mut values);
            values[first + i] = self.defined[i].eval(&mut values);
        }
        for expression in self.updates.iter().chain(&self.defined) {
            expression.prepare(&mut values);
        }
        let states = self.names.states();
        let mut x = vec![0.0; states.len()];
        for (i, expression) in self.initial.iter().enumerate() {
            x[i] = expression.eval(&mut values);
            values[states.start + i] = x[i];
        }
        self.check_states(&x, 0.0, theta)?;
        let inputs: Vec<Vec<f64>> = (0..record.n_inputs())
            .map(|j| record.input(j).to_vec())
            .collect();
        let mut y = vec![vec![0.0; n]; n_outputs];
        let mut rk4 = Rk4::new(x.len());
        let t_step = self.sample_time;
        let system = Rhs {
            model: self,
            inputs: &inputs,
            values: RefCell::new(values.clone()),
            sample: Cell::new(0),
            inputs_of: Cell::new(usize::MAX),
        };
        let mut dx = vec![0.0; x.len()];
        for k in 0..n {
            let t_k = k as f64 * t_step;
            if self.measure == Measure::Start {
                self.measure_outputs(&mut values, (t_k, k, &x), &inputs, (&mut y, k))?;
            }
            system.sample.set(k);
            match self.time {
                Time::Continuous { substeps } => {
                    let h = t_step / substeps as f64;
                    for s in 0..substeps {
                        let t = t_k + s as f64 * h;
                        match self.integrator {
                            Integrator::Rk4 => rk4.step(&system, t, h, &mut x),
                            Integrator::Euler => {
                                system.rhs(t, &x, &mut dx);
                                for (xi, d) in x.iter_mut().zip(&dx) {
                                    *xi += h * d;
                                }
                            }
                        }
                        if let Some(rng) = noise.as_deref_mut() {
                            self.add_process_noise(&mut x, rng, h.sqrt());
                        }
                        self.check_states(&x, t + h, theta)?;
                    }
                }
                Time::Discrete => {
                    // Measured at the start, the table holds this
                    // sample's time, inputs and states already.
                    if self.measure != Measure::Start {
                        self.set_time_and_inputs(&mut values, (t_k, k), &inputs);
                    }
                    self.step_program.run_with(&mut values, &x, &mut dx);
                    std::mem::swap(&mut x, &mut dx);
                    if let Some(rng) = noise.as_deref_mut() {
                        self.add_process_noise(&mut x, rng, 1.0);
                    }
                    self.check_states(&x, t_k + t_step, theta)?;
                }
            }
            if self.measure == Measure::End {
                let (t, next) = (t_k + t_step, (k + 1).min(n - 1));
                self.measure_outputs(&mut values, (t, next, &x), &inputs, (&mut y, k))?;
            }
            if let Some(rng) = noise.as_deref_mut() {
                for &(j, sd) in &self.lognormal {
                    let z: f64 = StandardNormal.sample(rng);
                    y[j][k] *= (sd * z).exp();
                }
            }
        }
        for (j, column) in y.iter().enumerate() {
            record.output_mut(j).copy_from_slice(column);
        }
        Ok(())
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

/// The states' derivatives for the RK4 integrator: the value table and
/// its sample are cells because the integrator borrows the system
/// immutably.
struct Rhs<'a> {
    model: &'a EquationModel,
    inputs: &'a [Vec<f64>],
    values: RefCell<Vec<f64>>,
    /// The sample interval being integrated (for held inputs).
    sample: Cell<usize>,
    /// The sample whose held inputs the table holds.
    inputs_of: Cell<usize>,
}

impl OdeSystem for Rhs<'_> {
    fn dim(&self) -> usize {
        self.model.updates.len()
    }

    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
        let model = self.model;
        let mut values = self.values.borrow_mut();
        let sample = self.sample.get();
        if model.input_path == InputPath::Hold {
            // Held inputs change at samples only: set once a sample.
            values[TIME_SLOT] = t;
            if self.inputs_of.get() != sample {
                model.set_time_and_inputs(&mut values, (t, sample), self.inputs);
                self.inputs_of.set(sample);
            }
        } else {
            model.set_time_and_inputs(&mut values, (t, sample), self.inputs);
        }
        model.step_program.run_with(&mut values, x, dx);
    }
}

// The states move into the value table through a list of slots rather
// than `copy_from_slice`: a model has a few states, and the call of
// `memmove` that a copy of a range becomes (even written as a loop) cost
// more than the equations between (perf on the tanks model: 16% of its
// time).

/// `x` into the table's `slots`.
#[inline]
fn scatter(values: &mut [f64], slots: &[usize], x: &[f64]) {
    for (&slot, &v) in slots.iter().zip(x) {
        values[slot] = v;
    }
}

/// The index and sd of each positive sd.
fn noisy(sds: impl IntoIterator<Item = f64>) -> Vec<(usize, f64)> {
    sds.into_iter()
        .enumerate()
        .filter(|&(_, sd)| sd > 0.0)
        .collect()
}

/// Names defined twice, or clashing with a parameter, an input, `t` or a
/// function, are refused.
fn check_names(
    spec: &ModelSpec,
    states: &[String],
    defined: &[String],
) -> Result<(), EquationError> {
    let functions: Vec<&str> = EquationOps::make().iter().map(|op| op.repr()).collect();
    let mut seen: Vec<(&str, &str)> = vec![("t", "the time")];
    seen.extend(
        spec.param_names()
            .iter()
            .map(|n| (n.as_str(), "a parameter")),
    );
    seen.extend(spec.input_names().iter().map(|n| (n.as_str(), "an input")));
    let ours = states
        .iter()
        .map(|n| (n.as_str(), "a state"))
        .chain(defined.iter().map(|n| (n.as_str(), "an equation")));
    for (name, what) in ours {
        let fail = |message: String| EquationError {
            equation: name.to_string(),
            position: None,
            message,
        };
        if !is_identifier(name) {
            return Err(fail(format!(
                "`{name}` is not a name: use letters, digits and _, starting with a letter"
            )));
        }
        if functions.contains(&name) {
            return Err(fail(format!(
                "`{name}` is a function: give {what} another name"
            )));
        }
        if let Some((_, other)) = seen.iter().find(|(n, _)| *n == name) {
            return Err(fail(format!(
                "`{name}` is {what} and already {other}: give each a name of its own"
            )));
        }
        seen.push((name, what));
    }
    Ok(())
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && chars.all(|c| c.is_alphanumeric() || c == '_')
}

/// For each of the model's outputs, the index of its equation among the
/// defined quantities (intermediates first).
fn output_indices(text: &EquationsText, spec: &ModelSpec) -> Result<Vec<usize>, EquationError> {
    let fail = |equation: &str, message: String| EquationError {
        equation: equation.to_string(),
        position: None,
        message,
    };
    let model_outputs = spec.output_names();
    if let Some(extra) = text
        .outputs
        .iter()
        .find(|e| !model_outputs.contains(&e.name))
    {
        return Err(fail(
            &extra.name,
            format!(
                "is not an output of the model (its outputs: {}); an intermediate quantity \
                 goes among the definitions",
                model_outputs.join(", ")
            ),
        ));
    }
    model_outputs
        .iter()
        .map(|name| {
            text.outputs
                .iter()
                .position(|e| &e.name == name)
                .map(|i| text.definitions.len() + i)
                .ok_or_else(|| {
                    fail(
                        name,
                        "the output has no equation: give one (`NAME = \"...\"` among the \
                         outputs)"
                            .into(),
                    )
                })
        })
        .collect()
}

/// An order of the defined quantities in which each comes after those it
/// reads; a cycle is refused, named.
fn evaluation_order(
    defined: &[Expression],
    first: usize,
    names: &[String],
) -> Result<Vec<usize>, EquationError> {
    let reads = |i: usize| -> Vec<usize> {
        defined[i]
            .reads()
            .iter()
            .filter(|&&s| s >= first)
            .map(|&s| s - first)
            .collect()
    };
    // 0: not visited, 1: on the current path, 2: done.
    let mut mark = vec![0u8; defined.len()];
    let mut order = Vec::with_capacity(defined.len());
    fn visit(
        i: usize,
        reads: &dyn Fn(usize) -> Vec<usize>,
        mark: &mut [u8],
        order: &mut Vec<usize>,
        path: &mut Vec<usize>,
    ) -> Result<(), Vec<usize>> {
        match mark[i] {
            2 => return Ok(()),
            1 => {
                let from = path.iter().position(|&p| p == i).unwrap_or(0);
                let mut cycle = path[from..].to_vec();
                cycle.push(i);
                return Err(cycle);
            }
            _ => {}
        }
        mark[i] = 1;
        path.push(i);
        for j in reads(i) {
            visit(j, reads, mark, order, path)?;
        }
        path.pop();
        mark[i] = 2;
        order.push(i);
        Ok(())
    }
    for i in 0..defined.len() {
        visit(i, &reads, &mut mark, &mut order, &mut Vec::new()).map_err(|cycle| {
            let named: Vec<&str> = cycle.iter().map(|&c| names[c].as_str()).collect();
            EquationError {
                equation: named[0].to_string(),
                position: None,
                message: format!(
                    "the equations depend on each other in a cycle: {}; break it (a quantity \
                     that needs its own past is a state)",
                    named.join(" -> ")
                ),
            }
        })?;
    }
    Ok(order)
}

/// Which defined quantities the slots `reads` need, directly or through
/// other defined quantities.
fn needed_by(reads: &[usize], defined: &[Expression], first: usize) -> Vec<bool> {
    let mut needed = vec![false; defined.len()];
    let mut stack: Vec<usize> = reads
        .iter()
        .filter(|&&s| s >= first)
        .map(|&s| s - first)
        .collect();
    while let Some(i) = stack.pop() {
        if !needed[i] {
            needed[i] = true;
            stack.extend(
                defined[i]
                    .reads()
                    .iter()
                    .filter(|&&s| s >= first)
                    .map(|&s| s - first),
            );
        }
    }
    needed
}

/// Which defined quantities read only parameters (directly or through
/// others like them): the same all through a record. `order` puts each
/// after those it reads.
fn per_record(order: &[usize], defined: &[Expression], names: &Names) -> Vec<bool> {
    let first = names.defined().start;
    let mut constant = vec![false; defined.len()];
    for &i in order {
        constant[i] = defined[i]
            .reads()
            .iter()
            .all(|&s| names.parameters().contains(&s) || (s >= first && constant[s - first]));
    }
    constant
}

#[cfg(test)]
mod tests {
    // A panic is how a test fails.
    #![allow(clippy::unwrap_used)]

    use rand::RngExt;
    use twostage_models::{Prior, experiment_rng};

    use super::*;
    use crate::{Equation, State};

    /// Every function and operator, in the derivatives and the outputs.
    fn every_function() -> EquationModel {
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

    #[test]
    fn compiled_code_gives_the_interpreters_bits() {
        let model = every_function();
        assert!(model.step_program.is_native() && model.measure_program.is_native());
        let mut rng = experiment_rng(7, 0);
        let n_states = model.state_slots.len();
        for trial in 0..2000 {
            let table: Vec<f64> = (0..model.table.values().len())
                .map(|_| awkward(&mut rng))
                .collect();
            let x: Vec<f64> = (0..n_states).map(|_| awkward(&mut rng)).collect();
            let (mut by_code, mut by_interpreter) = (table.clone(), table.clone());
            let (mut dx_code, mut dx_interpreter) = (vec![0.0; n_states], vec![0.0; n_states]);
            model.step_program.run_with(&mut by_code, &x, &mut dx_code);
            model
                .step_program
                .interpret(&mut by_interpreter, &x, &mut dx_interpreter);
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
