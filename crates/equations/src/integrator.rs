//! Integrator steps of a continuous-time model as one program: the
//! stages of RK4 (or Euler's one) and the states' update wrapped around
//! the derivatives' program, one or several steps in a row, so
//! that they are one call of compiled code rather than one call a stage
//! through the models crate's integrator. The arithmetic is that of the
//! models crate's `Rk4::step` (and of `x += h f`), operation for operation
//! and in its order, so the states come out the same bits; the tests hold
//! the two side by side.

use crate::expression::{Program, Table, slot_index};
use crate::instruction::Instruction;
use crate::{Integrator, TIME_SLOT};

/// Instructions a program of several steps may hold, at most: beyond,
/// fewer steps a call (a longer program only adds compile time).
const MAX_INSTRUCTIONS: usize = 2000;

/// Compiled steps and where their caller writes what changes each step.
#[derive(Debug, Clone)]
pub(crate) struct IntegratorStep {
    /// Reads the states from its vector `x`, gives the states
    /// `starts.len()` steps later back in `out`.
    pub(crate) program: Program,
    /// Each step's slot of its start time.
    pub(crate) starts: Vec<usize>,
    /// Each step's slots of the inputs at its stage times (RK4: the
    /// start, the middle and the end of the step; Euler: the start), in
    /// input order. Empty where the inputs are held through the sample:
    /// then they sit in their own slots all along.
    pub(crate) stage_inputs: Vec<Vec<Vec<usize>>>,
}

impl IntegratorStep {
    /// `steps` steps of size `h` in a row by `integrator` around
    /// `derivatives` (which reads the states from its vector and gives
    /// their derivatives back); `inputs` are the table's input slots,
    /// whose values the caller writes at each stage time unless `held`.
    pub(crate) fn new(
        derivatives: &Program,
        integrator: Integrator,
        (h, steps): (f64, usize),
        inputs: &[usize],
        held: bool,
        table: &mut Table,
    ) -> Self {
        let (code, states, slopes) = derivatives.parts();
        let n = states.len();
        let time = slot_index(TIME_SLOT);
        let starts: Vec<usize> = (0..steps).map(|_| table.fresh()).collect();
        let stage_times = match integrator {
            Integrator::Rk4 => 3,
            Integrator::Euler => 1,
        };
        let stage_inputs: Vec<Vec<Vec<usize>>> = match held || inputs.is_empty() {
            true => Vec::new(),
            false => (0..steps)
                .map(|_| {
                    (0..stage_times)
                        .map(|_| inputs.iter().map(|_| table.fresh()).collect())
                        .collect()
                })
                .collect(),
        };
        let (step, next, scratch) = (
            fresh_slots(table, n),
            fresh_slots(table, n),
            fresh_slots(table, n),
        );
        let (k1, k2, k3) = (
            fresh_slots(table, n),
            fresh_slots(table, n),
            fresh_slots(table, n),
        );
        let half = 0.5 * h;
        let sixth = h / 6.0;
        let [h, half, sixth, two] = [h, half, sixth, 2.0].map(|v| slot_index(table.number(v)));
        let (middle, end) = (slot_index(table.fresh()), slot_index(table.fresh()));
        let mut out = Vec::new();
        // The stage at time `at` (a slot), its inputs those of stage time
        // `which` of step `j`: the table's time and inputs set, then the
        // derivatives.
        let stage = |out: &mut Vec<Instruction>, at: u32, (j, which): (usize, usize)| {
            out.push(Instruction::Copy([at, time]));
            if let Some(values) = stage_inputs.get(j).and_then(|s| s.get(which)) {
                for (&value, &input) in values.iter().zip(inputs) {
                    out.push(Instruction::Copy([slot_index(value), slot_index(input)]));
                }
            }
            out.extend_from_slice(code);
        };
        // `to = x + a k` for each state (Rk4's `offset`, Euler's update).
        let offset = |out: &mut Vec<Instruction>, to: &[u32], a: u32, k: &[u32]| {
            for i in 0..n {
                out.push(Instruction::Mul([a, k[i], scratch[i]]));
                out.push(Instruction::Add([step[i], scratch[i], to[i]]));
            }
        };
        let keep = |out: &mut Vec<Instruction>, k: &[u32]| {
            for i in 0..n {
                out.push(Instruction::Copy([slopes[i], k[i]]));
            }
        };
        for (j, &start) in starts.iter().enumerate() {
            let start = slot_index(start);
            // A step's states end in the state slots, where the next step
            // reads them; the last step's in the vector given back.
            let to = if j + 1 == steps { &next } else { states };
            // The states at the step's start, kept: the stages overwrite
            // the state slots.
            for i in 0..n {
                out.push(Instruction::Copy([states[i], step[i]]));
            }
            match integrator {
                Integrator::Euler => {
                    stage(&mut out, start, (j, 0));
                    offset(&mut out, to, h, slopes);
                }
                Integrator::Rk4 => {
                    stage(&mut out, start, (j, 0));
                    keep(&mut out, &k1);
                    out.push(Instruction::Add([start, half, middle]));
                    offset(&mut out, states, half, &k1);
                    stage(&mut out, middle, (j, 1));
                    keep(&mut out, &k2);
                    offset(&mut out, states, half, &k2);
                    stage(&mut out, middle, (j, 1));
                    keep(&mut out, &k3);
                    out.push(Instruction::Add([start, h, end]));
                    offset(&mut out, states, h, &k3);
                    stage(&mut out, end, (j, 2));
                    // x + sixth (k1 + 2 (k2 + k3) + k4), k4 in the slopes.
                    for i in 0..n {
                        let s = scratch[i];
                        out.push(Instruction::Add([k2[i], k3[i], s]));
                        out.push(Instruction::Mul([two, s, s]));
                        out.push(Instruction::Add([k1[i], s, s]));
                        out.push(Instruction::Add([s, slopes[i], s]));
                        out.push(Instruction::Mul([sixth, s, s]));
                        out.push(Instruction::Add([step[i], s, to[i]]));
                    }
                }
            }
        }
        let mut program = Program::from_parts(out, states, &next);
        program.compile();
        Self {
            program,
            starts,
            stage_inputs,
        }
    }

    /// How many steps of the derivatives' program, whose code is
    /// `instructions` long, one call may take within `substeps` a sample:
    /// the most that divide them and keep the program within
    /// [`MAX_INSTRUCTIONS`] (at least 1).
    pub(crate) fn steps_a_call(instructions: usize, substeps: usize) -> usize {
        // A step: the derivatives four times and a few instructions a
        // state; counted generously.
        let per_step = 4 * instructions + 64;
        (1..=substeps)
            .rev()
            .find(|&g| substeps.is_multiple_of(g) && g * per_step <= MAX_INSTRUCTIONS)
            .unwrap_or(1)
    }
}

/// `count` slots of their own.
fn fresh_slots(table: &mut Table, count: usize) -> Vec<u32> {
    (0..count).map(|_| slot_index(table.fresh())).collect()
}
