//! A model's equations compiled: the value table's layout, each right
//! side's slots, the order in which the defined quantities are evaluated;
//! a record's response is in `response`.

mod response;

use exmex::MakeOperators;

use crate::expression::{Expression, Program, Table};
use crate::integrator::IntegratorStep;
use crate::ops::EquationOps;
use crate::{EquationError, EquationsText, InputPath, Measure, Names, TIME_SLOT, Time};
pub(crate) use response::LANES;
use response::Stepping;
use twostage_models::ModelSpec;

/// Equations compiled for one model: see the crate's example.
#[derive(Debug, Clone)]
pub struct EquationModel {
    names: Names,
    /// The value table's slots beyond the names: numbers and the
    /// instructions' results.
    table: Table,
    time: Time,
    measure: Measure,
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
    /// How the states move from one sample to the next.
    stepping: Stepping,
    /// The same for [`LANES`] records side by side.
    wide: Stepping,
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
        let stepping = match text.time {
            Time::Continuous { substeps } => {
                let h = spec.sample_time() / substeps as f64;
                let inputs: Vec<usize> = names.inputs().collect();
                let held = text.inputs == InputPath::Hold;
                // Process noise comes between steps: one a call then.
                let per_call = match text.states.iter().all(|s| s.noise_sd == 0.0) {
                    true => IntegratorStep::steps_a_call(step.parts().0.len(), substeps),
                    false => 1,
                };
                let mut integrator_step = |steps| {
                    IntegratorStep::new(
                        &step,
                        text.integrator,
                        (h, steps),
                        &inputs,
                        held,
                        &mut table,
                    )
                };
                Stepping::Integrated {
                    substeps,
                    steps: Box::new(integrator_step(per_call)),
                    one: Box::new(integrator_step(1)),
                    #[cfg(test)]
                    derivatives: step,
                }
            }
            Time::Discrete => {
                step.compile();
                Stepping::Discrete { next: step }
            }
        };
        let wide = stepping.lanes(LANES, table.len());
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
            input_path: text.inputs,
            sample_time: spec.sample_time(),
            initial,
            updates,
            process_noise: noisy(text.states.iter().map(|s| s.noise_sd)),
            defined: defined_expressions,
            constant_order,
            stepping,
            wide,
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
