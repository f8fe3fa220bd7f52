//! A parameter that belongs to each record (issue 72, item 2): a lag's
//! initial state, marked `per_record = true`.
//!
//! - `estimate --joint` fits the plant's parameters once and each
//!   record's initial state on its own: one row `joint[K]` per record.
//! - `simulate --at --input --own-from-first K` fits a record's initial
//!   state to its first K samples, the plant held at the row's values,
//!   and predicts the rest from there.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{field, path, rows, scratch, simulate_beside, text, train_small, twostage};

const MODEL: &str = r#"
[model]
name = "lag"
description = "a first-order lag from its own initial state"

[[parameter]]
name = "a"
prior = { dist = "uniform", low = 0.5, high = 3.0 }

[[parameter]]
name = "b"
prior = { dist = "uniform", low = 0.5, high = 3.0 }

[[parameter]]
name = "x0"
prior = { dist = "uniform", low = -3.0, high = 3.0 }
per_record = true

[signals]
inputs = ["u"]
outputs = ["y"]
samples = 400
sample_time = 0.05

[input]
signal = "multisine"
band = [0.0, 2.0]
rms = [0.2, 2.0]

[equations]
states = [{ name = "x", initial = "x0", derivative = "b * u - a * x" }]
outputs = { y = "x" }

[noise]
output_sd = 0.01
"#;

/// The first number after `what` in `said`.
fn number_after(said: &str, what: &str) -> f64 {
    let at = said
        .find(what)
        .unwrap_or_else(|| panic!("{what} in {said}"))
        + what.len();
    said[at..]
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .find(|s| !s.is_empty())
        .unwrap()
        .parse()
        .unwrap()
}

const STARTS: [f64; 3] = [2.5, -2.0, 1.0];

#[test]
fn the_joint_fit_gives_each_record_its_own_initial_state() {
    let dir = scratch("own_parameters_joint");
    let model = dir.join("lag.toml");
    std::fs::write(&model, MODEL).unwrap();
    let records: Vec<String> = STARTS
        .iter()
        .enumerate()
        .map(|(i, x0)| simulate_beside(&model, &format!("1.5,2.0,{x0}"), i))
        .collect();
    let estimator = train_small(&model);
    let mut args = vec![
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--refine",
        "--joint",
    ];
    args.extend(records.iter().map(String::as_str));
    let out = twostage(&args);
    let said = text(&out.stderr);
    assert!(out.status.success(), "{said}");
    let table = rows(&text(&out.stdout));
    assert_eq!(table.len(), 2 * STARTS.len(), "{table:?}");
    let joint = &table[STARTS.len()..];
    for (k, ((id, row), x0)) in joint.iter().zip(STARTS).enumerate() {
        assert_eq!(id, &format!("joint[{k}]"));
        // The plant's parameters are one; the initial states each record's.
        assert_eq!(field(row, "a").to_bits(), field(&joint[0].1, "a").to_bits());
        assert!((field(row, "a") - 1.5).abs() < 0.03, "{row:?}");
        assert!((field(row, "x0") - x0).abs() < 0.05, "{row:?}");
        assert!(field(row, "x0_hi") - field(row, "x0_lo") < 0.2, "{row:?}");
    }
    assert!(
        said.contains("x0 belongs to each record (per_record in the model file)"),
        "{said}"
    );
    // Different initial states are not a disagreement between records.
    assert!(!said.contains("lie beyond their intervals"), "{said}");

    // The same records with one initial state forced on all: one row
    // `joint`, its x0 a compromise that fits none of them.
    let shared = dir.join("shared.toml");
    std::fs::write(&shared, MODEL.replace("per_record = true\n", "")).unwrap();
    args[4] = path(&shared);
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let table = rows(&text(&out.stdout));
    let (id, row) = table.last().unwrap();
    assert_eq!(id, "joint");
    assert!(
        STARTS
            .iter()
            .filter(|x0| (field(row, "x0") - *x0).abs() > 0.3)
            .count()
            >= 2,
        "{row:?}"
    );
}

#[test]
fn another_record_is_predicted_from_its_own_first_samples() {
    let dir = scratch("own_parameters_predict");
    let model = dir.join("lag.toml");
    std::fs::write(&model, MODEL).unwrap();
    let other = simulate_beside(&model, "1.5,2.0,-2.0", 1);
    // The plant as estimated on another record, which started at 2.5.
    let estimate = dir.join("estimate.csv");
    std::fs::write(&estimate, "experiment,a,b,x0\n0,1.5,2.0,2.5\n").unwrap();
    // `simulate --at` of the estimate on the other record through `model`.
    let simulate_at = |model: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "simulate",
            "--model-file",
            path(model),
            "--at",
            path(&estimate),
            "--input",
            &other,
        ];
        args.extend(extra);
        twostage(&args)
    };
    let predict = |extra: &[&str]| {
        let out = simulate_at(&model, &[&["--noiseless"], extra].concat());
        let said = text(&out.stderr);
        assert!(out.status.success(), "{said}");
        (text(&out.stdout), said)
    };
    let (_, plain) = predict(&[]);
    let (predicted, own) = predict(&["--own-from-first", "40"]);
    let x0 = number_after(
        &own,
        "its own parameters fitted to its first 40 samples: x0 = ",
    );
    assert!((x0 + 2.0).abs() < 0.05, "{own}");
    // The whole record: from the record's own start the prediction is
    // within the noise (sd 0.01); from the other record's, far off.
    let (rms_plain, rms_own) = (number_after(&plain, "y RMS "), number_after(&own, "y RMS "));
    assert!(
        rms_own < 0.02 && rms_plain > 5.0 * rms_own,
        "{plain}\n{own}"
    );
    let first: f64 = predicted
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(2)
        .unwrap()
        .parse()
        .unwrap();
    // The first sample is the fitted initial state (said to four digits).
    assert!((first - x0).abs() < 1e-3, "{predicted}");

    // What it refuses, and why.
    for (extra, says) in [
        (&["--own-from-first", "0"][..], "its first 1 to 400 samples"),
        (
            &["--own-from-first", "401"][..],
            "its first 1 to 400 samples",
        ),
    ] {
        let out = simulate_at(&model, extra);
        assert!(!out.status.success());
        assert!(text(&out.stderr).contains(says), "{}", text(&out.stderr));
    }
    let shared = dir.join("shared.toml");
    std::fs::write(&shared, MODEL.replace("per_record = true\n", "")).unwrap();
    let out = simulate_at(&shared, &["--own-from-first", "40"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr)
            .contains("mark an initial state or a sensor offset with per_record = true"),
        "{}",
        text(&out.stderr)
    );
}
