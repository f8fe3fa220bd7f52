//! A model file from the shell: print the template, train, inspect,
//! validate and simulate with it, and read a mistake's line.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{path, scratch, text, twostage};

#[test]
fn the_template_trains_validates_and_simulates_an_estimator() {
    let dir = scratch("model-file-template");
    let out = twostage(&["models", "--template"]);
    assert!(out.status.success());
    let model = dir.join("model.toml");
    // A smaller run than the template's preset, for the test's time.
    let template = text(&out.stdout).replace("sims = 1500", "sims = 300");
    std::fs::write(&model, template).unwrap();
    // `models` describes the file's model as it does the built-in ones:
    // its priors, record and presets (the file's, then its built-in
    // source's).
    let out = twostage(&["models", "--model-file", path(&model)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let described = text(&out.stdout);
    assert!(described.starts_with("benchmark-normal: "), "{described}");
    assert!(
        described.contains("parameter theta  prior truncnormal(mu = 0, sigma = 0.4)"),
        "{described}"
    );
    assert!(described.contains("N = 500"), "{described}");
    assert!(
        described.contains("presets   default, paper, recommended"),
        "{described}"
    );
    let estimator = dir.join("est.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--validate",
        "200",
        "--calibrate",
        "200",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = twostage(&["inspect", path(&estimator)]);
    let shown = text(&out.stdout);
    assert!(shown.contains("model       benchmark-normal"), "{shown}");
    assert!(
        shown.contains("prior truncnormal(mu = 0, sigma = 0.4) on [-0.9, 0.9]"),
        "{shown}"
    );
    assert!(shown.contains("N = 500"), "{shown}");
    assert!(
        shown.contains("m = 300 records (0 failed), seed 1, simulated, Uniform design"),
        "{shown}"
    );
    // Validation simulates the model again: from the file, which it needs.
    let out = twostage(&["validate", "--estimator", path(&estimator), "--sims", "100"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains(
            "--model-file: the estimator was trained on 'benchmark-normal', not a built-in \
             model: give the model file it was trained from"
        ),
        "{}",
        text(&out.stderr)
    );
    let out = twostage(&[
        "validate",
        "--estimator",
        path(&estimator),
        "--sims",
        "100",
        "--model-file",
        path(&model),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("r = 100 records unseen in training"));
    // And `simulate` writes the file's records: 500 samples each.
    let out = twostage(&["simulate", "--model-file", path(&model), "--theta", "0.3"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let csv = text(&out.stdout);
    assert_eq!(csv.lines().next(), Some("u,y"));
    assert_eq!(csv.lines().count(), 501);
}

#[test]
fn a_mistake_in_a_model_file_is_one_line_naming_file_line_and_key() {
    let dir = scratch("model-file-mistake");
    let model = dir.join("bad.toml");
    std::fs::write(
        &model,
        "[model]\nname = \"m\"\n[source]\nbuiltin = \"benchmark\"\n[[parameter]]\nname = \"t\"\n\
         prior = { dist = \"uniform\", low = 1.0, high = 0.0 }\n",
    )
    .unwrap();
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--out",
        path(&dir.join("x")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(
        err.contains("bad.toml, line 7, key `parameter.prior`: parameter 't'"),
        "{err}"
    );
    assert!(
        err.contains("lower bound must be below the upper bound"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    // --model and --model-file are one or the other.
    let out = twostage(&[
        "train",
        "--model",
        "benchmark",
        "--model-file",
        path(&model),
        "--out",
        path(&dir.join("x")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let out = twostage(&["train", "--out", path(&dir.join("x"))]);
    assert_eq!(out.status.code(), Some(2));
    // The classic methods are the built-in models': refused for a model file.
    std::fs::write(
        &model,
        "[model]\nname = \"m\"\n[source]\nbuiltin = \"benchmark\"\n",
    )
    .unwrap();
    let out = twostage(&[
        "estimate",
        "--model-file",
        path(&model),
        "--method",
        "pem",
        path(&dir.join("r.csv")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("method 'pem' is not available for m"));
}

#[test]
fn a_chart_simulated_elsewhere_trains_from_the_shell() {
    let dir = scratch("model-file-chart");
    // A model file without a source: its charts come from files.
    let model = dir.join("short.toml");
    std::fs::write(
        &model,
        "[model]\nname = \"short\"\n[[parameter]]\nname = \"theta\"\n\
         prior = { dist = \"uniform\", low = -0.9, high = 0.9 }\n\
         [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 300\n\
         [[preset]]\nname = \"small\"\ncompress = \"arx:5,5\"\nfit = \"mlp:8\"\n",
    )
    .unwrap();
    // The chart made "elsewhere": here by the built-in benchmark, shortened.
    let maker = dir.join("maker.toml");
    std::fs::write(
        &maker,
        "[model]\nname = \"maker\"\n[source]\nbuiltin = \"benchmark\"\n[signals]\nsamples = 300\n",
    )
    .unwrap();
    let chart = dir.join("chart");
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&maker),
        "--count",
        "700",
        "--seed",
        "4",
        "--out-dir",
        path(&chart),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let estimator = dir.join("est.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&chart),
        "--validate",
        "150",
        "--calibrate",
        "150",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report = text(&out.stdout);
    assert!(report.contains("trained on the chart"), "{report}");
    assert!(
        report.contains("150 records held out of it at random"),
        "{report}"
    );
    assert!(
        report.contains("r = 150 records unseen in training"),
        "{report}"
    );
    let shown = text(&twostage(&["inspect", path(&estimator)]).stdout);
    assert!(shown.contains("m = 400 records (0 failed)"), "{shown}");
    // Without a source the model cannot simulate: said, not attempted.
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--out",
        path(&estimator),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("has no [source]"));
    // A broken chart is one line naming the file and the line.
    std::fs::write(chart.join("truth.csv"), "experiment,beta\n0,0.1\n").unwrap();
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&chart),
        "--out",
        path(&estimator),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(
        err.contains("truth.csv, line 1: header 'experiment,beta'"),
        "{err}"
    );
}
