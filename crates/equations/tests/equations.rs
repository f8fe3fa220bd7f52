//! Equations against hand-written Rust of the same models, and the
//! mistakes a model file can hold.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rand_distr::{Distribution, StandardNormal};
use twostage_equations::{
    Equation, EquationError, EquationModel, EquationSimulator, EquationsText, Measure, State, Time,
};
use twostage_models::{
    Conditions, InputSignal, IoData, ModelSpec, Prior, SimError, Simulator, experiment_rng,
};

fn spec(params: &[&str], inputs: &[&str], outputs: &[&str], dt: f64, n: usize) -> ModelSpec {
    let lo = vec![0.0; params.len()];
    let hi = vec![10.0; params.len()];
    ModelSpec::new("m", params, Prior::uniform_box(&lo, &hi).unwrap(), dt, n)
        .unwrap()
        .with_signals(inputs, outputs)
}

fn compile(text: &EquationsText, spec: &ModelSpec) -> Result<EquationModel, EquationError> {
    EquationModel::compile(text, spec)
}

#[test]
fn an_oscillator_follows_its_closed_form() {
    // x'' = -w^2 x from x = 1, v = 0: x(t) = cos(w t).
    let spec = spec(&["w"], &[], &["y"], 0.1, 100);
    let text = EquationsText {
        time: Time::Continuous { substeps: 20 },
        states: vec![
            State::new("x", "1", "v"),
            State::new("v", "0", "-(w^2) * x"),
        ],
        outputs: vec![Equation::new("y", "x")],
        ..EquationsText::default()
    };
    let model = compile(&text, &spec).unwrap();
    let mut record = IoData::zeros(100, 0, 1);
    model.respond(&[2.0], &mut record, None).unwrap();
    for (k, y) in record.output(0).iter().enumerate() {
        let exact = (2.0 * 0.1 * k as f64).cos();
        assert!((y - exact).abs() < 1e-7, "sample {k}: {y} against {exact}");
    }
    // Measured at the end of each interval: one sample later.
    let later = EquationsText {
        measure: Measure::End,
        ..text
    };
    let model = compile(&later, &spec).unwrap();
    model.respond(&[2.0], &mut record, None).unwrap();
    assert!((record.output(0)[0] - 0.2f64.cos()).abs() < 1e-7);
}

#[test]
fn a_discrete_model_with_noise_matches_the_same_loop_by_hand() {
    // x[k+1] = a x[k] + b u[k] + 0.1 e[k]; y[k] = x[k] exp(0.05 z[k]).
    let spec = spec(&["a", "b"], &["u"], &["y"], 1.0, 40);
    let mut state = State::new("x", "1 + b", "a * x + b * u");
    state.noise_sd = 0.1;
    let text = EquationsText {
        time: Time::Discrete,
        states: vec![state],
        outputs: vec![Equation::new("y", "x")],
        lognormal_sd: vec![0.05],
        ..EquationsText::default()
    };
    let model = compile(&text, &spec).unwrap();
    let simulator = EquationSimulator::new(
        spec.clone(),
        model,
        Some(InputSignal::white_gaussian(1.0).unwrap()),
    );
    let mut record = spec.new_record();
    let (a, b) = (0.7, 0.4);
    simulator
        .simulate(&[a, b], &mut experiment_rng(3, 5), &mut record)
        .unwrap();
    // By hand, drawing from the same stream in the documented order: the
    // input, then at each sample the process noise and the output noise.
    let mut rng = experiment_rng(3, 5);
    let u: Vec<f64> = (0..40).map(|_| StandardNormal.sample(&mut rng)).collect();
    assert_eq!(record.input(0), u.as_slice());
    let mut x: f64 = 1.0 + b;
    for (k, uk) in u.iter().enumerate() {
        let y = x;
        let e: f64 = StandardNormal.sample(&mut rng);
        x = a * x + b * uk + 0.1 * e;
        let z: f64 = StandardNormal.sample(&mut rng);
        let y = y * (0.05 * z).exp();
        assert!((record.output(0)[k] - y).abs() < 1e-12, "sample {k}");
    }
    // Without noise, the same input: the noise-free loop.
    let mut quiet = spec.new_record();
    let given = Conditions {
        noiseless: true,
        input: Some(&record),
    };
    simulator
        .simulate_under(&[a, b], &mut experiment_rng(9, 9), given, &mut quiet)
        .unwrap();
    let mut x: f64 = 1.0 + b;
    for (k, uk) in u.iter().enumerate() {
        assert!((quiet.output(0)[k] - x).abs() < 1e-12);
        x = a * x + b * uk;
    }
}

#[test]
fn the_functions_and_the_piecewise_value_match_rust() {
    // The input sweeps values; each output is one function of it.
    let spec = spec(&["p"], &["u"], &["clip", "s", "f", "m", "c"], 1.0, 9);
    let text = EquationsText {
        time: Time::Discrete,
        states: vec![],
        // `root` reads only a parameter: evaluated once per record.
        definitions: vec![
            Equation::new("half", "u / 2"),
            Equation::new("root", "sqrt(p)"),
        ],
        outputs: vec![
            Equation::new("clip", "if u < -1 then -1 else u > 1 then 1 else u"),
            Equation::new("s", "sat(u, p) + sign(u)"),
            Equation::new(
                "f",
                "exp(-(u^2)) * cosh(half) + atan2(u, 2) - abs(u) / sqrt(p)",
            ),
            Equation::new("m", "min(u, 0.5) * max(u, -0.5) + (u >= 0) * 10 + (u != 0)"),
            Equation::new("c", "if u == 0 then tanh(t) else log(p) + t"),
        ],
        ..EquationsText::default()
    };
    let model = compile(&text, &spec).unwrap();
    let mut record = IoData::zeros(9, 1, 5);
    let us = [-3.0, -1.0, -0.6, -0.25, 0.0, 0.25, 0.6, 1.0, 3.0];
    record.input_mut(0).copy_from_slice(&us);
    let p: f64 = 0.8;
    model.respond(&[p], &mut record, None).unwrap();
    for (k, &u) in us.iter().enumerate() {
        let t = k as f64;
        let sign = if u == 0.0 { 0.0 } else { u.signum() };
        let expected = [
            u.clamp(-1.0, 1.0),
            u.clamp(-p, p) + sign,
            (-u * u).exp() * (u / 2.0).cosh() + u.atan2(2.0) - u.abs() / p.sqrt(),
            u.min(0.5) * u.max(-0.5)
                + if u >= 0.0 { 10.0 } else { 0.0 }
                + if u != 0.0 { 1.0 } else { 0.0 },
            if u == 0.0 { t.tanh() } else { p.ln() + t },
        ];
        for (j, e) in expected.iter().enumerate() {
            let got = record.output(j)[k];
            assert!(
                (got - e).abs() < 1e-12,
                "output {j} at u = {u}: {got} against {e}"
            );
        }
    }
}

#[test]
fn a_state_that_becomes_nan_fails_its_record_named() {
    let spec = spec(&["k"], &[], &["y"], 0.5, 20);
    let text = EquationsText {
        time: Time::Continuous { substeps: 5 },
        states: vec![State::new("level", "1", "-k * sqrt(level) - 1")],
        outputs: vec![Equation::new("y", "level")],
        ..EquationsText::default()
    };
    let model = compile(&text, &spec).unwrap();
    let mut record = IoData::zeros(20, 0, 1);
    let error = model.respond(&[1.0], &mut record, None).unwrap_err();
    match &error {
        SimError::NonFiniteState { state, time, .. } => {
            assert_eq!(state, "level");
            // The level empties at about t = 0.6 (dx/dt <= -1 from 1).
            assert!(*time > 0.3 && *time < 1.5, "{time}");
        }
        other => panic!("{other}"),
    }
    assert!(
        error.to_string().contains("the state level became NaN"),
        "{error}"
    );
}

fn error_of(text: &EquationsText, spec: &ModelSpec) -> EquationError {
    compile(text, spec).unwrap_err()
}

#[test]
fn mistakes_are_refused_at_load_named() {
    let spec = spec(&["a"], &["u"], &["y"], 1.0, 10);
    let base = EquationsText {
        states: vec![State::new("x", "0", "a * x + u")],
        outputs: vec![Equation::new("y", "x")],
        ..EquationsText::default()
    };
    let with_output = |text: &str| EquationsText {
        outputs: vec![Equation::new("y", text)],
        ..base.clone()
    };
    // A syntax error: the equation and the position.
    let e = error_of(&with_output("x * (a + "), &spec);
    assert_eq!(e.equation, "y");
    assert!(e.message.contains("cannot parse"), "{e}");
    // An unknown name, with the known ones.
    let e = error_of(&with_output("x + b"), &spec);
    assert_eq!((e.equation.as_str(), e.position), ("y", Some(4)));
    assert!(
        e.message.contains("unknown name `b`") && e.message.contains("t, a, u, x, y"),
        "{e}"
    );
    // An equation too large to parse in reasonable time and stack: its
    // size named, and what to do; one of the largest size compiles.
    let sum = |terms: usize| vec!["x"; terms].join(" + ");
    let e = error_of(&with_output(&sum(200_001)), &spec);
    assert_eq!(e.equation, "y");
    assert!(
        e.message
            .contains("200000 operators in one equation, at most 10000")
            && e.message.contains("`define`"),
        "{e}"
    );
    let (small, large) = (
        compile(&with_output("x"), &spec).unwrap(),
        compile(&with_output(&sum(2_001)), &spec).unwrap(),
    );
    let (mut x, mut y) = (IoData::zeros(10, 1, 1), IoData::zeros(10, 1, 1));
    for record in [&mut x, &mut y] {
        record.input_mut(0).fill(1.0);
    }
    small.respond(&[0.5], &mut x, None).unwrap();
    large.respond(&[0.5], &mut y, None).unwrap();
    // y = 2001 x: the whole sum evaluated.
    for (a, b) in x.output(0).iter().zip(y.output(0)) {
        assert!((b - 2001.0 * a).abs() <= 1e-9 * b.abs().max(1.0), "{a} {b}");
    }
    assert!(x.output(0)[9] > 0.0);
    // A minus before a power, which exmex would read as (-x)^2.
    for (text, at) in [
        ("-x^2", 0),
        ("a * -x^2", 4),
        ("2 - (-sin(x)^2)", 5),
        ("-(x + a)^2", 0),
    ] {
        let e = error_of(&with_output(text), &spec);
        assert_eq!(e.position, Some(at), "{text}: {e}");
        assert!(e.message.contains("write -(x^2) or (-x)^2"), "{e}");
    }
    // Not a power, or a minus that is binary: accepted.
    for text in ["-x * 2", "a - x^2", "x^-2", "-(x^2)", "(-x)^2", "-x"] {
        compile(&with_output(text), &spec).unwrap();
    }
    // A then without its else.
    let e = error_of(&with_output("if x > 0 then x"), &spec);
    assert!(e.message.contains("`else"), "{e}");
    // An initial value that reads a state defined after it.
    let mut later = base.clone();
    later.states = vec![State::new("x", "z + 1", "-x"), State::new("z", "a", "-z")];
    let e = error_of(&later, &spec);
    assert_eq!(e.equation, "x.initial");
    assert!(e.message.contains("before it is defined"), "{e}");
    // A cycle among the defined quantities.
    let mut cycle = base.clone();
    cycle.definitions = vec![Equation::new("p", "q + 1"), Equation::new("q", "2 * p")];
    let e = error_of(&cycle, &spec);
    assert!(e.message.contains("p -> q -> p"), "{e}");
    // An output the model does not have, or one missing.
    let mut extra = base.clone();
    extra.outputs.push(Equation::new("z", "x"));
    assert!(error_of(&extra, &spec).message.contains("not an output"));
    let mut missing = base.clone();
    missing.outputs.clear();
    missing.definitions = vec![Equation::new("w", "x")];
    assert_eq!(error_of(&missing, &spec).equation, "y");
    // A state named as a parameter, or as a function.
    let mut clash = base.clone();
    clash.states[0].name = "a".into();
    assert!(
        error_of(&clash, &spec)
            .message
            .contains("already a parameter")
    );
    clash.states[0].name = "sin".into();
    assert!(error_of(&clash, &spec).message.contains("is a function"));
    // No steps.
    let zero = EquationsText {
        time: Time::Continuous { substeps: 0 },
        ..base
    };
    assert_eq!(error_of(&zero, &spec).equation, "substeps");
}

/// Numbers in exponent notation read as Rust reads them, in any place an
/// expression holds a number; an `e` without digits after it is no
/// exponent.
#[test]
fn numbers_in_exponent_notation_are_numbers() {
    let spec = spec(&["a"], &[], &["y"], 1.0, 3);
    let output = |expression: &str| {
        let text = EquationsText {
            time: Time::Discrete,
            states: vec![State::new("x", "0", "x")],
            outputs: vec![Equation::new("y", expression)],
            ..EquationsText::default()
        };
        let mut record = IoData::zeros(3, 0, 1);
        let model = compile(&text, &spec)?;
        model.respond(&[2.0], &mut record, None).unwrap();
        Ok::<f64, EquationError>(record.output(0)[0])
    };
    for (expression, value) in [
        ("2.0e5 * a", 4.0e5),
        ("1E-3 + a", 2.001),
        ("a * 2.5e+2", 500.0),
        (".5e1 - a", 3.0),
        ("3. * a", 6.0),
        ("a^2e0", 4.0),
    ] {
        let got = output(expression).unwrap();
        assert!(
            (got - value).abs() < 1e-12 * value.abs(),
            "{expression}: {got}"
        );
    }
    // `2e` is no number: said, as a syntax mistake.
    assert!(output("2e * a").is_err());
}
