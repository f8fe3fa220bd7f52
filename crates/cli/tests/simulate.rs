//! The `twostage` binary as a user runs it.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn twostage(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twostage"))
        .args(args)
        .output()
        .expect("the twostage binary runs")
}

fn stdout(out: &Output) -> String {
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8(out.stderr.clone()).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Parse a CSV of numbers into its header and rows.
fn read_csv(text: &str) -> (String, Vec<Vec<f64>>) {
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_string();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

fn read_file(path: &Path) -> (String, Vec<Vec<f64>>) {
    read_csv(&std::fs::read_to_string(path).unwrap())
}

#[test]
fn models_lists_both_models_with_their_boxes() {
    let out = twostage(&["models"]);
    assert!(out.status.success());
    let text = stdout(&out);
    for needle in [
        "benchmark:",
        "theta  prior uniform on [-0.9, 0.9]",
        "N = 1000",
        "pacejka:",
        "pK1    prior uniform on [-42.83, -27.32]",
        "pK2    prior uniform on [-1.22, -0.98]",
        "N = 500 (sampled every 0.02 s)",
        "variance 0.01",
        "methods   ekf, ukf, pf, pem, ii, bayes",
        "methods   pf, pem, ii, bayes",
        "presets   paper",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
}

#[test]
fn one_noiseless_car_record_matches_the_golden_values() {
    let out = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--theta",
        "-35,-1.1",
        "--noiseless",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (header, rows) = read_csv(&stdout(&out));
    // Columns named as the car's signals.
    assert_eq!(header, "delta,a_y");
    assert_eq!(rows.len(), 500);
    // pacejka-golden.csv, t = 6 s and t = 4 s.
    assert!((rows[300][1] - 5.98522057067).abs() < 1e-8);
    assert!((rows[200][0] + 0.170710678119).abs() < 1e-11);
}

#[test]
fn the_same_seed_gives_the_same_record_and_another_seed_does_not() {
    let run = |seed: &str| {
        stdout(&twostage(&[
            "simulate",
            "--model",
            "benchmark",
            "--theta",
            "0.3",
            "--seed",
            seed,
        ]))
    };
    let a = run("5");
    assert_eq!(a, run("5"));
    assert_ne!(a, run("6"));
    let (header, rows) = read_csv(&a);
    assert_eq!(header, "u,y");
    assert_eq!(rows.len(), 1000);
}

#[test]
fn out_writes_the_record_to_a_file() {
    let dir = scratch("out_file");
    let path = dir.join("one.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--theta=-0.5",
        "--out",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).is_empty());
    assert_eq!(read_file(&path).1.len(), 1000);
}

#[test]
fn count_mode_writes_long_format_data_and_truth_that_reproduce() {
    let dir = scratch("count_mode");
    let out = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--count",
        "300",
        "--seed",
        "11",
        "--out-dir",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (data_header, data) = read_file(&dir.join("data.csv"));
    let (truth_header, truth) = read_file(&dir.join("truth.csv"));
    assert_eq!(data_header, "experiment,delta,a_y");
    assert_eq!(truth_header, "experiment,pK1,pK2");
    assert_eq!(data.len(), 300 * 500);
    assert_eq!(truth.len(), 300);
    for (i, row) in truth.iter().enumerate() {
        assert_eq!(row[0] as usize, i);
        assert!((-42.83..=-27.32).contains(&row[1]) && (-1.22..=-0.98).contains(&row[2]));
    }
    // Experiment 257 (in the second parallel block) simulated again alone,
    // from its printed truth: the very same record, bit for bit.
    let i = 257;
    let theta = format!("{},{}", truth[i][1], truth[i][2]);
    let alone = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--theta",
        &theta,
        "--seed",
        "11",
        "--experiment",
        "257",
    ]);
    assert!(alone.status.success(), "{}", stderr(&alone));
    let (_, rows) = read_csv(&stdout(&alone));
    let chart_rows: Vec<&Vec<f64>> = data.iter().filter(|r| r[0] as usize == i).collect();
    assert_eq!(chart_rows.len(), 500);
    for (a, b) in rows.iter().zip(chart_rows) {
        assert_eq!(a[0].to_bits(), b[1].to_bits());
        assert_eq!(a[1].to_bits(), b[2].to_bits());
    }
}

fn assert_usage_error(args: &[&str], needle: &str) {
    let out = twostage(args);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains(needle), "{args:?}: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: not one line:\n{err}"
    );
}

#[test]
fn bad_calls_get_one_clear_line_and_exit_code_2() {
    assert_usage_error(
        &["simulate", "--model", "pacejka", "--theta", "-35"],
        "expected 2 parameter values (pK1,pK2), got 1",
    );
    assert_usage_error(
        &["simulate", "--model", "benchmark", "--theta", "1.2"],
        "theta = 1.2 lies outside the prior box [-0.9, 0.9]",
    );
    assert_usage_error(
        &["simulate", "--model", "tractor", "--theta", "1"],
        "unknown model 'tractor': the built-in models are benchmark, pacejka",
    );
    assert_usage_error(&["simulate", "--model", "benchmark", "--theta", "x"], "'x'");
    assert_usage_error(&["simulate", "--model", "benchmark"], "give either --theta");
}

#[test]
fn outside_the_prior_works_when_allowed_and_divergence_fails_cleanly() {
    let ok = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--theta",
        "0.95",
        "--allow-outside-prior",
    ]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    let bad = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--theta",
        "3",
        "--allow-outside-prior",
    ]);
    assert_eq!(bad.status.code(), Some(1));
    let err = stderr(&bad);
    assert!(
        err.contains("diverged") && err.contains("theta = [3.0]"),
        "{err}"
    );
    assert!(stdout(&bad).is_empty(), "no partial CSV on failure");
}

/// The benchmark's noise-free response to `u` at `theta`, from eq. (5)
/// written out here: x1' = x1/2 + u, x2' = a x1 - theta x2 + b u, y = x2.
fn benchmark_response(theta: f64, u: &[f64]) -> Vec<f64> {
    let a = (1.0 - theta * theta) * (50.0 * theta * theta).sin();
    let b = theta / (1.0 + theta * theta);
    let (mut x1, mut x2) = (0.0f64, 0.0f64);
    u.iter()
        .map(|&u| {
            let y = x2;
            (x1, x2) = (0.5 * x1 + u, a * x1 - theta * x2 + b * u);
            y
        })
        .collect()
}

#[test]
fn simulate_at_estimates_predicts_on_a_measured_input() {
    let dir = scratch("simulate_at");
    let record = dir.join("record.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--theta",
        "0.3",
        "--seed",
        "4",
        "--out",
        record.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (_, measured) = read_file(&record);
    let u: Vec<f64> = measured.iter().map(|r| r[0]).collect();
    // Rows as `estimate` writes them, with a record it could not estimate.
    let estimates = dir.join("estimates.csv");
    std::fs::write(
        &estimates,
        "experiment,theta,theta_lo,theta_hi\nA,0.3,0.2,0.4\nfailed,,,\nB,-0.55,-0.6,-0.5\n",
    )
    .unwrap();
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--at",
        estimates.to_str().unwrap(),
        "--input",
        record.to_str().unwrap(),
        "--noiseless",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("experiment failed) has no estimate: skipped"));
    let text = stdout(&out);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("experiment,u,y"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2000);
    for (id, theta, part) in [("A", 0.3, &rows[..1000]), ("B", -0.55, &rows[1000..])] {
        let expected = benchmark_response(theta, &u);
        for (k, row) in part.iter().enumerate() {
            assert_eq!(row[0], id);
            assert_eq!(row[1].parse::<f64>().unwrap().to_bits(), u[k].to_bits());
            let y: f64 = row[2].parse().unwrap();
            assert!(
                (y - expected[k]).abs() <= 1e-9 * (1.0 + expected[k].abs()),
                "{id} {k}"
            );
        }
    }
    // Mistakes are named: a missing parameter column, a value that is not
    // a number (with its line).
    std::fs::write(&estimates, "experiment,gain\nA,0.3\n").unwrap();
    let at = [
        "simulate",
        "--model",
        "benchmark",
        "--at",
        estimates.to_str().unwrap(),
    ];
    let out = twostage(&at);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("no column `theta`"),
        "{}",
        stderr(&out)
    );
    std::fs::write(&estimates, "experiment,theta\nA,0.3\nB,abc\n").unwrap();
    let out = twostage(&at);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("line 3, column theta: \"abc\""),
        "{}",
        stderr(&out)
    );
    let short = dir.join("short.csv");
    std::fs::write(&short, "u,y\n1,0\n2,0\n").unwrap();
    std::fs::write(&estimates, "experiment,theta\nA,0.3\n").unwrap();
    // A record of another length is simulated at its own.
    let out = twostage(&[&at[..], &["--input", short.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).lines().count(), 1 + 2, "{}", stdout(&out));
}

/// A full standard output is named as the place that failed, with what to
/// do (Linux's /dev/full refuses every write); a closed one (`| head`) is
/// not an error.
#[test]
fn a_full_standard_output_is_named() {
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        return;
    };
    for args in [
        &["simulate", "--model", "benchmark", "--theta", "0.3"][..],
        &["models"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_twostage"))
            .args(args)
            .stdout(full.try_clone().unwrap())
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let said = stderr(&out);
        assert!(
            said.contains("writing to standard output") && said.contains("--out"),
            "{args:?}: {said}"
        );
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_twostage"))
        .args(["simulate", "--model", "benchmark", "--theta", "0.3"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A count no disk holds is refused before anything is drawn or written,
/// with the size it would take and the count that fits; a small one says
/// up front what it will take.
#[test]
fn a_count_the_disk_cannot_hold_is_refused_up_front() {
    let dir = scratch("simulate-huge");
    let target = dir.join("chart");
    let out = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--count",
        "1000000000000000",
        "--out-dir",
        target.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let said = stderr(&out);
    assert!(
        said.contains("--count 1000000000000000 would write up to")
            && said.contains("free: at most --count"),
        "{said}"
    );
    assert!(!target.exists(), "nothing is written");
    let small = twostage(&[
        "simulate",
        "--model",
        "benchmark",
        "--count",
        "3",
        "--out-dir",
        target.to_str().unwrap(),
    ]);
    assert!(small.status.success(), "{}", stderr(&small));
    let written = std::fs::metadata(target.join("data.csv")).unwrap().len();
    let said = stderr(&small);
    let bound: f64 = said
        .split("up to ")
        .nth(1)
        .and_then(|s| s.split(" kB").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{said}"));
    assert!(
        written as f64 <= bound * 1000.0,
        "{written} bytes against {said}"
    );
}

/// A header of a hundred thousand columns (a hostile or broken file) is
/// named by its row and its beginning, not echoed whole: the message stays
/// a line, whichever reader meets it.
#[test]
fn a_header_of_many_columns_makes_a_short_message() {
    let dir = scratch("wide-header");
    let header: Vec<String> = ["u".to_string(), "y".to_string()]
        .into_iter()
        .chain((0..100_000).map(|i| format!("z{i}")))
        .collect();
    let record = dir.join("wide.csv");
    std::fs::write(&record, format!("{}\n1,2\n", header.join(","))).unwrap();
    let estimator = dir.join("b.tse");
    let trained = twostage(&[
        "train",
        "--model",
        "benchmark",
        "--sims",
        "100",
        "--compress",
        "arx:2,2",
        "--fit",
        "linear",
        "--validate",
        "0",
        "--calibrate",
        "0",
        "--quiet",
        "--out",
        estimator.to_str().unwrap(),
    ]);
    assert!(trained.status.success(), "{}", stderr(&trained));
    let out = twostage(&[
        "estimate",
        "--estimator",
        estimator.to_str().unwrap(),
        record.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let said = stderr(&out);
    assert!(said.len() < 2000, "{} bytes: {}", said.len(), &said[..300]);
    assert!(
        said.contains("row 1: header 'u,y,z0,") && said.contains("characters)"),
        "{said}"
    );
}
