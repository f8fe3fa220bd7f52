//! The compiled steps and records side by side against the models
//! crate's integrator and each record alone.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::cell::RefCell;

use rand::RngExt;
use twostage_models::{InputSignal, ModelSpec, OdeSystem, Prior, Rk4, experiment_rng};

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
                None => match self.model.input_path {
                    InputPath::Linear => {
                        InputSignal::linear_value_at(t, self.model.sample_time, samples)
                    }
                    _ => InputSignal::sampled_value_at(t, self.model.sample_time, samples),
                },
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
        for path in [InputPath::Cubic, InputPath::Linear, InputPath::Hold] {
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
/// streams each has alone: with cubic, linear and held inputs, both
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
            Time::Continuous { substeps: 4 },
            Integrator::Rk4,
            InputPath::Cubic,
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
