//! `estimate --samples N --sharpen M`: draws sharpened through the model
//! (decision 100), against the closed-form posterior of a model linear in
//! its parameters with Gaussian noise and a Gaussian prior.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{field, ok, path, rows, scratch, text, twostage};

/// y = m + k u + noise (sd 2), m and k normal(0, 1) a priori: the
/// posterior is normal, its precision I + X'X / 4 for X = [1, u].
const MODEL: &str = r#"
[model]
name = "line"
description = "a level and a gain, seen through loud noise"

[[parameter]]
name = "m"
prior = { dist = "normal", mu = 0.0, sigma = 1.0 }

[[parameter]]
name = "k"
prior = { dist = "normal", mu = 0.0, sigma = 1.0 }

[signals]
inputs = ["u"]
outputs = ["y"]
samples = 30
sample_time = 0.1

[input]
signal = "multisine"
band = [0.0, 3.0]
rms = [0.5, 1.0]

[equations]
states = [{ name = "x", initial = "m", derivative = "0" }]
outputs = { y = "x + k * u" }

[noise]
output_sd = 2.0
"#;

/// The posterior mean and sds of (m, k) given a record's u and y.
fn exact_posterior(u: &[f64], y: &[f64]) -> ([f64; 2], [f64; 2]) {
    let v = 4.0;
    let (n, su, suu) = (
        u.len() as f64,
        u.iter().sum::<f64>(),
        u.iter().map(|x| x * x).sum::<f64>(),
    );
    let (sy, suy) = (
        y.iter().sum::<f64>(),
        u.iter().zip(y).map(|(a, b)| a * b).sum::<f64>(),
    );
    let a = [1.0 + n / v, su / v, su / v, 1.0 + suu / v];
    let det = a[0] * a[3] - a[1] * a[2];
    let inverse = [a[3] / det, -a[1] / det, -a[2] / det, a[0] / det];
    let b = [sy / v, suy / v];
    (
        [
            inverse[0] * b[0] + inverse[1] * b[1],
            inverse[2] * b[0] + inverse[3] * b[1],
        ],
        [inverse[0].sqrt(), inverse[3].sqrt()],
    )
}

/// Sharpened draws have the closed-form posterior's mean (within a tenth
/// of its sd) and sds (within 6%), with 8000 runs a round: a fitted
/// likelihood's mean errs by about sqrt(p / m) of the posterior's sd for
/// `p` features (here 28) and `m` runs a round; the same seed writes the
/// same bytes;
/// asking for sharpening without draws, with too few runs, or with values
/// to test is refused with what to do.
#[test]
fn sharpened_draws_are_the_closed_form_posterior() {
    let dir = scratch("sharpened");
    let model = dir.join("line.toml");
    std::fs::write(&model, MODEL).unwrap();
    let estimator = dir.join("line.tsest");
    ok(&[
        "train",
        "--model-file",
        path(&model),
        "--compress",
        "raw",
        "--fit",
        "linear",
        "--posterior",
        "1",
        "--sims",
        "400",
        "--validate",
        "0",
        "--calibrate",
        "0",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    let records = dir.join("records");
    ok(&[
        "simulate",
        "--model-file",
        path(&model),
        "--count",
        "3",
        "--seed",
        "11",
        "--out-dir",
        path(&records),
    ]);
    let data = records.join("data.csv");
    let draws_at = |name: &str, extra: &[&str]| {
        let file = dir.join(name);
        let mut args = vec![
            "estimate",
            "--estimator",
            path(&estimator),
            "--model-file",
            path(&model),
            "--samples",
            "20000",
            "--draws",
            path(&file),
        ];
        args.extend_from_slice(extra);
        args.push(path(&data));
        ok(&args);
        std::fs::read_to_string(&file).unwrap()
    };
    let sharpened = draws_at("sharp.csv", &["--sharpen", "24000"]);
    assert_eq!(
        sharpened,
        draws_at("again.csv", &["--sharpen", "24000"]),
        "the same seed, other draws"
    );
    let record_rows = rows(&std::fs::read_to_string(&data).unwrap());
    let drawn = rows(&sharpened);
    for experiment in ["0", "1", "2"] {
        let of = |table: &[(String, Vec<(String, f64)>)], name: &str| -> Vec<f64> {
            table
                .iter()
                .filter(|(id, _)| id == experiment)
                .map(|(_, fields)| field(fields, name))
                .collect()
        };
        let (mean, sd) = exact_posterior(&of(&record_rows, "u"), &of(&record_rows, "y"));
        for (j, name) in ["m", "k"].iter().enumerate() {
            let values = of(&drawn, name);
            assert_eq!(values.len(), 20000);
            let n = values.len() as f64;
            let got = values.iter().sum::<f64>() / n;
            let spread = (values.iter().map(|v| (v - got).powi(2)).sum::<f64>() / n).sqrt();
            assert!(
                (got - mean[j]).abs() < 0.1 * sd[j],
                "experiment {experiment}, {name}: mean {got} against {}",
                mean[j]
            );
            assert!(
                (spread / sd[j] - 1.0).abs() < 0.06,
                "experiment {experiment}, {name}: sd {spread} against {}",
                sd[j]
            );
        }
    }
    let refused = |extra: &[&str]| {
        let mut args = vec![
            "estimate",
            "--estimator",
            path(&estimator),
            "--model-file",
            path(&model),
        ];
        args.extend_from_slice(extra);
        args.push(path(&data));
        let out = twostage(&args);
        assert!(!out.status.success(), "{extra:?} was not refused");
        text(&out.stderr)
    };
    assert!(refused(&["--sharpen", "400"]).contains("--samples"));
    assert!(refused(&["--samples", "10", "--sharpen", "2"]).contains("at least 6"));
    let values = dir.join("values.csv");
    std::fs::write(&values, "m,k\n0.1,0.2\n").unwrap();
    assert!(
        refused(&["--samples", "10", "--sharpen", "400", "--at", path(&values)])
            .contains("without sharpening")
    );
}
