//! The automatic design through the command line's doors: a model file
//! without presets trained on a chart searches by itself and says so, the
//! design comes back as a `[[preset]]`, an output transform travels with
//! the estimator to the measured record, and a budget too short is said
//! before anything runs.
#![allow(clippy::unwrap_used)]

mod common;

use std::fmt::Write as _;
use std::path::Path;

use common::{path, scratch, text, twostage};

const GROWTH: &str = r#"
[model]
name = "growth"
[[parameter]]
name = "rate"
prior = { dist = "uniform", low = 0.1, high = 0.5 }
[[parameter]]
name = "size"
prior = { dist = "uniform", low = 1.0, high = 10.0 }
[signals]
inputs = []
outputs = ["n"]
samples = 10
"#;

/// A uniform number in [0, 1) from a counter (splitmix64), so the chart
/// needs no random crate and is the same everywhere.
fn uniform(counter: u64) -> f64 {
    let mut z = counter.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)) as f64 / 2f64.powi(64)
}

/// Populations size * exp(rate k) with multiplicative noise: positive,
/// spanning more than a decade.
fn growth(rate: f64, size: f64, noise: impl Fn(usize) -> f64) -> Vec<f64> {
    (0..10)
        .map(|k| size * (rate * k as f64).exp() * (0.1 * noise(k)).exp())
        .collect()
}

/// A chart of `m` growth records in the CSV layout.
fn write_chart(dir: &Path, m: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let (mut truth, mut data) = (
        "experiment,rate,size\n".to_string(),
        "experiment,n\n".to_string(),
    );
    for e in 0..m as u64 {
        let rate = 0.1 + 0.4 * uniform(3 * e);
        let size = 1.0 + 9.0 * uniform(3 * e + 1);
        writeln!(truth, "{e},{rate},{size}").unwrap();
        let noise = |k: usize| uniform(1_000_003 * (e + 1) + k as u64) * 3.46 - 1.73;
        for value in growth(rate, size, noise) {
            writeln!(data, "{e},{value}").unwrap();
        }
    }
    std::fs::write(dir.join("truth.csv"), truth).unwrap();
    std::fs::write(dir.join("data.csv"), data).unwrap();
}

/// A scratch folder with the growth model file and a chart of `m` records
/// in it; the model file's path.
fn growth_folder(name: &str, m: usize) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = scratch(name);
    let model = dir.join("growth.toml");
    std::fs::write(&model, GROWTH).unwrap();
    write_chart(&dir.join("chart"), m);
    (dir, model)
}

#[test]
fn a_model_without_presets_searches_on_its_chart_and_says_so() {
    let (dir, model) = growth_folder("auto-no-preset", 500);
    let est = dir.join("growth.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&dir.join("chart")),
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--out",
        path(&est),
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("growth has no preset: searching for a design"),
        "{stderr}"
    );
    assert!(
        stderr.contains("read the chart, search transforms"),
        "{stderr}"
    );
    // Every candidate applies to an input-less record: none failed.
    assert!(!stdout.contains("failed"), "{stdout}");
    assert!(
        stdout.contains("log+raw"),
        "the logarithm was tried:\n{stdout}"
    );
    let block = stdout
        .split("add to the model file:\n")
        .nth(1)
        .unwrap_or_else(|| panic!("a [[preset]] block in\n{stdout}"));
    assert!(
        block.starts_with("[[preset]]\nname = \"searched\"\ncompress = \""),
        "{block}"
    );
    let inspected = twostage(&["inspect", path(&est)]);
    let inspected = text(&inspected.stdout);
    assert!(
        inspected.contains("to train this structure again"),
        "{inspected}"
    );
    let compress_line = block.lines().nth(2).unwrap_or_default();
    assert!(
        inspected.contains(compress_line),
        "{compress_line} in\n{inspected}"
    );
}

#[test]
fn an_estimate_takes_a_sample_its_log_cannot_and_says_which() {
    let (dir, model) = growth_folder("auto-log-floor", 400);
    let est = dir.join("log.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&dir.join("chart")),
        "--compress",
        "log+raw",
        "--fit",
        "mlp:4",
        "--validate",
        "50",
        "--calibrate",
        "50",
        "--out",
        path(&est),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let mut records = "experiment,n\n".to_string();
    for (e, values) in [
        growth(0.3, 5.0, |_| 0.0),
        growth(0.3, 5.0, |_| 0.0)
            .into_iter()
            .enumerate()
            .map(|(k, v)| match k {
                3 => 0.0,
                6 => -2.0,
                _ => v,
            })
            .collect(),
    ]
    .iter()
    .enumerate()
    {
        for v in values {
            writeln!(records, "{e},{v}").unwrap();
        }
    }
    let data = dir.join("measured.csv");
    std::fs::write(&data, records).unwrap();
    let out = twostage(&["estimate", "--estimator", path(&est), path(&data)]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    let header: Vec<&str> = stdout.lines().next().unwrap().split(',').collect();
    let column = header
        .iter()
        .position(|h| *h == "untransformed_samples")
        .unwrap_or_else(|| panic!("the column in {stdout}"));
    let counts: Vec<&str> = stdout
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(column).unwrap())
        .collect();
    assert_eq!(counts, ["0", "2"], "{stdout}");
    assert!(
        stderr.contains("experiment 1: 2 sample(s) outside the domain")
            && stderr.contains("n = 0 at sample 4")
            && stderr.contains("n = -2 at sample 7"),
        "{stderr}"
    );
    assert!(!stderr.contains("experiment 0"), "{stderr}");
}

/// A time budget that searches on part of a chart still learns from all
/// of it: the winner's final fit takes every training record; a posterior
/// asked of the search has its components chosen, within the budget.
#[test]
fn every_record_of_a_chart_reaches_the_final_fit() {
    let (dir, model) = growth_folder("auto-whole-chart", 420);
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&dir.join("chart")),
        "--auto",
        "--budget-seconds",
        "3",
        "--validate",
        "10",
        "--calibrate",
        "10",
        "--posterior",
        "2",
        "--out",
        path(&dir.join("growth.tsest")),
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    // The search chooses the posterior's components by held-out
    // likelihood, the asked count the most.
    assert!(
        stderr.contains("posterior: ")
            && stderr.contains("the lowest held-out negative log-likelihood of [1, 2]"),
        "{stderr}"
    );
    // The density's share of the budget is said; the search, in the rest,
    // fits and scores on part of the chart.
    assert!(
        stderr.contains("the posterior's density is fitted within the time budget"),
        "{stderr}"
    );
    let searched: usize = stderr
        .split("the search fits and scores on the first ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{stderr}"));
    assert!(
        (50..400).contains(&searched)
            && stderr.contains(&format!(
                "first {searched} of the chart's 400 training records"
            ))
            && stderr.contains("the winner's final fit takes them all"),
        "{stderr}"
    );
    assert!(
        stdout.contains("trained further from its scored fit on 400 records")
            || stdout.contains("final fit on 400 records was stopped"),
        "{stdout}"
    );
}

#[test]
fn a_budget_too_short_for_calibration_and_validation_is_said_first() {
    let dir = scratch("auto-short-budget");
    let out = twostage(&[
        "train",
        "--model",
        "benchmark",
        "--auto",
        "--budget-seconds",
        "0.5",
        "--out",
        path(&dir.join("never.tsest")),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("even 100 calibration and 100 validation records take about")
            && stderr.contains("give at least"),
        "{stderr}"
    );
    assert!(!dir.join("never.tsest").exists());
}

#[test]
fn a_chart_too_small_to_search_on_says_how_many_it_needs() {
    let (dir, model) = growth_folder("auto-small-chart", 40);
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--chart",
        path(&dir.join("chart")),
        "--auto",
        "--validate",
        "10",
        "--calibrate",
        "10",
        "--out",
        path(&dir.join("never.tsest")),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("training records = 20") && stderr.contains("at least 50"),
        "{stderr}"
    );
    assert!(!dir.join("never.tsest").exists());
}
