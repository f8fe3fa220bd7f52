//! `estimate --at VALUES.csv --check`: given parameter values (a published
//! value, another tool's estimate) checked against records, and the
//! options that would not apply refused.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};

use common::{path, scratch, text, twostage};

/// `count` benchmark records of seed 21 under `dir/data`.
fn records(dir: &Path, count: usize) -> PathBuf {
    let data = dir.join("data");
    let count = count.to_string();
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--count",
        &count,
        "--seed",
        "21",
        "--out-dir",
        path(&data),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    data
}

/// The table's rows as maps from column to value.
fn table(csv: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut lines = csv.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(str::to_string))
                .collect()
        })
        .collect()
}

#[test]
fn the_true_values_explain_their_records_and_wrong_ones_do_not() {
    let dir = scratch("check-values");
    let data = records(&dir, 4);
    let (truth, records) = (data.join("truth.csv"), data.join("data.csv"));
    // The values of a file checked against the records, 99 of the model's
    // own records each: the table's rows and what stderr said.
    let checked = |values: &Path| {
        let out = twostage(&[
            "estimate",
            "--model",
            "benchmark",
            "--at",
            path(values),
            "--check",
            "--check-sims",
            "99",
            path(&records),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        (table(&text(&out.stdout)), text(&out.stderr))
    };
    let (rows, _) = checked(&truth);
    let truth_rows = table(&std::fs::read_to_string(&truth).unwrap());
    assert_eq!(rows.len(), 4);
    for (row, truth) in rows.iter().zip(&truth_rows) {
        // Each record is checked at its own row's values.
        assert_eq!(row["experiment"], truth["experiment"]);
        let (given, written) = (
            truth["theta"].parse::<f64>().unwrap(),
            row["theta"].parse::<f64>().unwrap(),
        );
        assert_eq!(given.to_bits(), written.to_bits());
        assert_eq!(row["explained"], "true", "{row:?}");
    }

    // One row for every record: a value far from all four truths.
    let far = dir.join("far.csv");
    let truths: Vec<f64> = truth_rows
        .iter()
        .map(|r| r["theta"].parse().unwrap())
        .collect();
    let value = if truths.iter().all(|t| (t - 0.85).abs() > 0.3) {
        0.85
    } else {
        -0.85
    };
    std::fs::write(&far, format!("theta\n{value}\n")).unwrap();
    let (rows, stderr) = checked(&far);
    assert_eq!(rows.len(), 4);
    let unexplained = rows.iter().filter(|r| r["explained"] == "false").count();
    assert!(unexplained >= 3, "{rows:?}");
    assert!(stderr.contains("not explained"));

    // Values 0.02 below the truths: on records 0 and 3 the misfit is still
    // one the model's noise makes, but the best fit beats the values by
    // more than that noise would: not explained, and the warning says
    // which test failed.
    let near = dir.join("near.csv");
    let below: String = truths
        .iter()
        .enumerate()
        .map(|(i, t)| format!("{i},{}\n", t - 0.02))
        .collect();
    std::fs::write(&near, format!("experiment,theta\n{below}")).unwrap();
    let (rows, stderr) = checked(&near);
    for i in [0, 3] {
        let row = &rows[i];
        assert_eq!(
            (row["model_consistent"].as_str(), row["explained"].as_str()),
            ("true", "false"),
            "{row:?}"
        );
        let improvement: f64 = row["check_improvement_tail_probability"].parse().unwrap();
        assert!(improvement <= 0.01, "{row:?}");
    }
    assert!(stderr.contains("improves on the estimate"));

    // A file of several rows must have one per record: the record without
    // its row is named, the others are checked.
    let partial = dir.join("partial.csv");
    let mut lines: Vec<&str> = std::fs::read_to_string(&truth)
        .unwrap()
        .leak()
        .lines()
        .collect();
    lines.remove(2);
    std::fs::write(&partial, lines.join("\n") + "\n").unwrap();
    let out = twostage(&[
        "estimate",
        "--model",
        "benchmark",
        "--at",
        path(&partial),
        "--check",
        path(&records),
    ]);
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("experiment 1") && stderr.contains("has no row for experiment 1"),
        "{stderr}"
    );
    assert_eq!(table(&text(&out.stdout)).len(), 3);
}

#[test]
fn values_outside_the_prior_or_without_a_parameter_are_refused_and_named() {
    let dir = scratch("check-values-refused");
    let data = records(&dir, 1);
    let records = data.join("data.csv");
    let outside = dir.join("outside.csv");
    std::fs::write(&outside, "experiment,theta\n0,1.5\n").unwrap();
    let run = |values: &Path, extra: &[&str]| {
        let mut args = vec![
            "estimate",
            "--model",
            "benchmark",
            "--at",
            path(values),
            "--check",
        ];
        args.extend(extra);
        args.push(path(&records));
        twostage(&args)
    };
    let out = run(&outside, &[]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("theta")
            && stderr.contains("1.5")
            && stderr.contains("--allow-outside-prior"),
        "{stderr}"
    );
    // Accepted when asked for: the model runs there, and the check says how
    // it fits.
    let out = run(&outside, &["--allow-outside-prior"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(table(&text(&out.stdout))[0]["theta"], "1.5");

    // `simulate --at` refuses them alike.
    let out = twostage(&["simulate", "--model", "benchmark", "--at", path(&outside)]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--allow-outside-prior"));
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--at",
        path(&outside),
        "--allow-outside-prior",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let nameless = dir.join("nameless.csv");
    std::fs::write(&nameless, "experiment,k\n0,0.1\n").unwrap();
    let out = run(&nameless, &[]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("no column `theta`"), "{stderr}");
}

#[test]
fn the_classic_methods_take_check_and_options_that_do_not_apply_are_refused() {
    let dir = scratch("check-methods");
    let data = records(&dir, 2);
    let records = data.join("data.csv");
    let out = twostage(&[
        "estimate",
        "--model",
        "benchmark",
        "--method",
        "ekf",
        "--check",
        "--check-sims",
        "49",
        path(&records),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let rows = table(&text(&out.stdout));
    assert_eq!(rows.len(), 2);
    for row in &rows {
        let tail: f64 = row["check_tail_probability"].parse().unwrap();
        assert!((0.0..=1.0).contains(&tail), "{row:?}");
        assert!(row["y_rms"].parse::<f64>().unwrap() > 0.0);
    }

    let refused = |args: &[&str], option: &str| {
        let mut all = vec!["estimate"];
        all.extend(args);
        all.push(path(&records));
        let out = twostage(&all);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = text(&out.stderr);
        assert!(stderr.contains(option), "{args:?}: {stderr}");
    };
    refused(
        &["--model", "benchmark", "--method", "ekf", "--starts", "3"],
        "--starts",
    );
    refused(
        &["--model", "benchmark", "--method", "pem", "--p0", "eq7"],
        "--p0",
    );
    refused(
        &[
            "--model",
            "benchmark",
            "--method",
            "ekf",
            "--particles",
            "10",
        ],
        "--particles",
    );
    refused(
        &["--model", "benchmark", "--method", "ukf", "--seed", "3"],
        "--seed",
    );
    refused(
        &["--model", "benchmark", "--method", "kalman"],
        "'kalman': use one of ekf, ukf, pf, pem, ii, bayes, oe",
    );
    // --at without --check would only echo the values.
    refused(
        &[
            "--model",
            "benchmark",
            "--at",
            path(&data.join("truth.csv")),
        ],
        "--check",
    );
}

/// A record longer than the model's (a validation record, say) is
/// predicted and checked at its own length.
#[test]
fn a_record_of_another_length_is_predicted_and_checked() {
    let dir = scratch("check-values-length");
    let long = dir.join("long.toml");
    std::fs::write(
        &long,
        "[model]\nname = \"benchmark\"\n[source]\nbuiltin = \"benchmark\"\n[[parameter]]\n\
         name = \"theta\"\nprior = { dist = \"uniform\", low = -0.9, high = 0.9 }\n\
         [signals]\nsamples = 2500\n",
    )
    .unwrap();
    let data = dir.join("long");
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&long),
        "--count",
        "2",
        "--seed",
        "4",
        "--out-dir",
        path(&data),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (truth, records) = (data.join("truth.csv"), data.join("data.csv"));
    let predicted = dir.join("predicted.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--at",
        path(&truth),
        "--input",
        path(&records),
        "--noiseless",
        "--out",
        path(&predicted),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let rows = std::fs::read_to_string(&predicted).unwrap().lines().count();
    assert_eq!(rows, 1 + 2 * 2500);
    let out = twostage(&[
        "estimate",
        "--model",
        "benchmark",
        "--at",
        path(&truth),
        "--check",
        "--check-sims",
        "99",
        path(&records),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for row in table(&text(&out.stdout)) {
        assert_eq!(row["explained"], "true", "{row:?}");
    }
}

/// `simulate --at --input --score-from K` scores the prediction on samples
/// K and after, `--score-to L` before L: the RMS it prints is the one
/// computed here from the files.
#[test]
fn a_prediction_is_scored_from_the_sample_asked() {
    let dir = scratch("score-from");
    let data = records(&dir, 1);
    let (truth, record) = (data.join("truth.csv"), data.join("data.csv"));
    let predicted = dir.join("predicted.csv");
    let run_to = |from: &str, to: Option<&str>| {
        let mut args = vec![
            "simulate",
            "--model",
            "benchmark",
            "--at",
            path(&truth),
            "--input",
            path(&record),
            "--noiseless",
            "--score-from",
            from,
            "--out",
            path(&predicted),
        ];
        if let Some(to) = to {
            args.extend(["--score-to", to]);
        }
        twostage(&args)
    };
    let run = |from: &str| run_to(from, None);
    let out = run("100");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    let printed: f64 = stderr
        .split("from sample 100: y RMS ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .unwrap_or_else(|| panic!("{stderr}"))
        .parse()
        .unwrap();
    let column = |file: &std::path::Path| -> Vec<f64> {
        std::fs::read_to_string(file)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
            .collect()
    };
    let (measured, simulated) = (column(&record), column(&predicted));
    assert_eq!(simulated.len(), 1000, "the CSV holds every sample");
    let tail: Vec<f64> = measured[100..]
        .iter()
        .zip(&simulated[100..])
        .map(|(a, b)| (a - b) * (a - b))
        .collect();
    let rms = (tail.iter().sum::<f64>() / tail.len() as f64).sqrt();
    assert!(
        (printed - rms).abs() <= 1e-3 * rms,
        "{printed} against {rms}"
    );
    // A window's end: samples 100 to 499.
    let out = run_to("100", Some("500"));
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let printed: f64 = stderr
        .split("from sample 100 to 499: y RMS ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .unwrap_or_else(|| panic!("{stderr}"))
        .parse()
        .unwrap();
    let window = &tail[..400];
    let rms = (window.iter().sum::<f64>() / window.len() as f64).sqrt();
    assert!(
        (printed - rms).abs() <= 1e-3 * rms,
        "{printed} against {rms}"
    );
    let out = run_to("100", Some("100"));
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--score-to 100: the window must end after its start (100)"),
        "{}",
        text(&out.stderr)
    );
    // Past the record's end: named, with the valid range.
    let out = run("1000");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("has 1000 samples (0 to 999)"),
        "{}",
        text(&out.stderr)
    );
}

/// The help's default for `--check-sims` is the library's: clap's doc
/// comments cannot name the constant, so the text holds its value.
#[test]
fn the_check_runs_help_names_the_library_default() {
    let out = twostage(&["estimate", "--help"]);
    assert!(out.status.success());
    let help = text(&out.stdout)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    let (_, after) = help
        .split_once("says how many ran). Default ")
        .unwrap_or_else(|| panic!("`estimate --help` names no default runs:\n{help}"));
    let digits: String = after.chars().take_while(char::is_ascii_digit).collect();
    assert_eq!(digits, twostage::DEFAULT_CHECK_RUNS.to_string(), "{help}");
}
