//! docs/real-data.md, run: a two-tank model identified from a "measured"
//! record of a plant it does not match (a leak it lacks, coloured sensor
//! noise), checked, refined, and validated by predicting another record.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{path, python, scratch, text, twostage};

fn example() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/examples/tanks")
}

/// The guide's model file in `dir`, its simulator named by absolute path
/// and run with the test's Python.
fn model_file(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(example().join("tanks.toml")).unwrap();
    let simulator = example().join("tanks.py");
    let command = format!("[{:?}, {:?}]", python(), simulator.to_str().unwrap());
    let text = text.replace(r#"["python3", "tanks.py"]"#, &command);
    assert!(
        text.contains(&command),
        "the guide's model file names its command otherwise"
    );
    let file = dir.join("tanks.toml");
    std::fs::write(&file, text).unwrap();
    file
}

/// The RMS `simulate --at ... --input validation.csv` reports.
fn validation_rms(model: &Path, estimates: &Path, validation: &Path) -> f64 {
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(model),
        "--at",
        path(estimates),
        "--input",
        path(validation),
        "--noiseless",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    let rms = stderr
        .split("level RMS ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .unwrap_or_else(|| panic!("no RMS in {stderr}"));
    rms.parse().unwrap()
}

/// One CSV row of `estimate`'s table as (header, values).
fn table(out: &std::process::Output) -> (Vec<String>, Vec<String>) {
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let mut lines = stdout.lines();
    let split = |l: &str| l.split(',').map(str::to_string).collect::<Vec<_>>();
    (split(lines.next().unwrap()), split(lines.next().unwrap()))
}

#[test]
fn a_mismatched_model_is_checked_refined_and_validated() {
    let dir = scratch("real-data");
    let made = Command::new(python())
        .arg(example().join("make_data.py"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", text(&made.stderr));
    let (estimation, validation) = (dir.join("estimation.csv"), dir.join("validation.csv"));
    let model = model_file(&dir);
    let estimator = dir.join("tanks.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--compress",
        "pca:8",
        "--fit",
        "mlp:10",
        "--sims",
        "1500",
        "--validate",
        "0",
        "--calibrate",
        "300",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    // Two-stage alone, checked against its record.
    let ts = dir.join("ts.csv");
    let plots = dir.join("plots");
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--check",
        "--plot",
        path(&plots),
        "--out",
        path(&ts),
        path(&estimation),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let svg = std::fs::read_to_string(plots.join("estimation.svg")).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("estimation: not explained"),
        "{svg:.200}"
    );
    // Refined through the model, and the multi-start output-error fit.
    let refined = dir.join("refined.csv");
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--refine",
        "--out",
        path(&refined),
        path(&estimation),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let oe = dir.join("oe.csv");
    let out = twostage(&[
        "estimate",
        "--method",
        "oe",
        "--model-file",
        path(&model),
        "--starts",
        "4",
        "--out",
        path(&oe),
        path(&estimation),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stop = std::fs::read_to_string(&refined).unwrap();
    // Why the best descent stopped, and what the search over the prior
    // found (its optima, the runner-up's loss over the best's).
    assert!(
        stop.lines()
            .next()
            .unwrap()
            .ends_with("refine_stop,optima,runner_up_over_best"),
        "{stop}"
    );
    // The refined row's interval is its own (from the loss's curvature
    // and the residuals), not the two-stage one moved to the refined point.
    let field = |text: &str, name: &str| -> f64 {
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let row: Vec<&str> = lines.next().unwrap().split(',').collect();
        let at = header.iter().position(|h| *h == name).unwrap();
        row[at].parse().unwrap()
    };
    let two_stage = std::fs::read_to_string(&ts).unwrap();
    for name in ["k", "a1", "a2", "h0"] {
        let width =
            |text: &str| field(text, &format!("{name}_hi")) - field(text, &format!("{name}_lo"));
        let (own, moved) = (width(&stop), width(&two_stage));
        let centre = field(&stop, name);
        assert!(
            own.is_finite() && own > 0.0 && (own - moved).abs() > 1e-6 * moved,
            "{name}: refined width {own}, two-stage {moved}"
        );
        assert!(
            field(&stop, &format!("{name}_lo")) < centre
                && centre < field(&stop, &format!("{name}_hi"))
        );
    }

    // Validation: each estimate predicts the other record's level.
    let [ts_rms, refined_rms, oe_rms] =
        [&ts, &refined, &oe].map(|estimates| validation_rms(&model, estimates, &validation));
    assert!(
        refined_rms <= ts_rms && refined_rms <= 1.02 * oe_rms,
        "validation RMS: two-stage {ts_rms}, refined {refined_rms}, output error {oe_rms}"
    );

    // Both records of the plant, jointly: one estimate after the
    // records' own, which predicts the validation record better than the
    // estimation record's refinement alone (it saw it), and fits both.
    let joint = dir.join("joint.csv");
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--joint",
        "--out",
        path(&joint),
        path(&estimation),
        path(&validation),
    ]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("note: joint estimate of 2 of 2 records"),
        "{stderr}"
    );
    let table_text = std::fs::read_to_string(&joint).unwrap();
    let lines: Vec<Vec<&str>> = table_text.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(lines.len(), 4, "{table_text}");
    assert!(
        lines.iter().all(|l| l.len() == lines[0].len()),
        "{table_text}"
    );
    assert_eq!(lines[3][0], "joint");
    let header = lines[0].clone();
    let joint_only = dir.join("joint-only.csv");
    std::fs::write(
        &joint_only,
        format!("{}\n{}\n", header.join(","), lines[3].join(",")),
    )
    .unwrap();
    let joint_rms = validation_rms(&model, &joint_only, &validation);
    assert!(
        joint_rms < refined_rms,
        "validation RMS: joint {joint_rms}, refined on the estimation record {refined_rms}"
    );
    let fits: Vec<f64> = stderr
        .split("fit at it: ")
        .nth(1)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .split(", ")
        .map(|f| {
            f.rsplit(' ')
                .next()
                .unwrap()
                .trim_end_matches('%')
                .parse()
                .unwrap()
        })
        .collect();
    assert!(
        fits.len() == 2 && fits.iter().all(|f| *f > 80.0),
        "{stderr}"
    );

    // The estimator learned the estimation record's input: on the
    // validation record (another input) its estimate is not explained.
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--check",
        path(&validation),
    ]);
    let (header, row) = table(&out);
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(row[column("explained")], "false");
    assert!(text(&out.stderr).contains("not explained"));
    // And it says why: the record's input is not the one it learned.
    assert_eq!(row[column("input_as_trained")], "false");
    assert!(
        text(&out.stderr).contains("its input pump differs from the one every training record had"),
        "{}",
        text(&out.stderr)
    );
    // On its own record the input is the trained one; the two-stage
    // estimate misses the record where the model need not (the best fit
    // near it is much closer), and the refined one is the best fit: it
    // passes, though the model is not exact for the plant.
    let ts_table = std::fs::read_to_string(&ts).unwrap();
    let ts_row: Vec<&str> = ts_table.lines().nth(1).unwrap().split(',').collect();
    let ts_header: Vec<&str> = ts_table.lines().next().unwrap().split(',').collect();
    let at = |name: &str| ts_header.iter().position(|h| *h == name).unwrap();
    assert_eq!(ts_row[at("input_as_trained")], "true", "{ts_table}");
    assert_eq!(ts_row[at("explained")], "false", "{ts_table}");
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--refine",
        "--check",
        "--correlation",
        path(&estimation),
    ]);
    let (header, row) = table(&out);
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(row[column("explained")], "true", "{header:?}\n{row:?}");
    // The refined estimate's correlations, one column per pair.
    let pairs: Vec<&String> = header.iter().filter(|h| h.starts_with("corr_")).collect();
    assert_eq!(pairs.len(), 6, "{header:?}");
    for name in ["corr_k_a1", "corr_k_h0", "corr_a2_h0"] {
        let r: f64 = row[column(name)].parse().unwrap();
        assert!((-1.0..=1.0).contains(&r) && r != 0.0, "{name} {r}");
    }
    assert_eq!(
        row[column("model_consistent")],
        "false",
        "{header:?}\n{row:?}"
    );
    assert!(text(&out.stderr).contains("the model is not exact for this record"));
    // Not even its best fit misses the record as the model's own records
    // do: the model, not the estimate, is what falls short.
    let best_fit: f64 = row[column("check_best_fit_tail_probability")]
        .parse()
        .unwrap();
    assert!(best_fit <= 0.01, "{header:?}\n{row:?}");
    // So the refined estimate is the best fit itself, not the posterior
    // mean near it, and its interval says what it covers there.
    let over_best: f64 = row[column("loss_over_best")].parse().unwrap();
    assert!((over_best - 1.0).abs() < 1e-12, "{header:?}\n{row:?}");
    assert!(
        text(&out.stderr).contains(
            "the refined estimate is the model's best fit itself, and its interval covers this \
             record's noise"
        ),
        "{}",
        text(&out.stderr)
    );

    // --refine=auto refines exactly the records whose two-stage estimate
    // the check does not explain (this one), to the same point.
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--refine=auto",
        path(&estimation),
    ]);
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(
            "--refine=auto: the check explains 0 of 1 two-stage estimates; refining experiment(s) \
             1 (not explained): estimation"
        ),
        "{stderr}"
    );
    let (auto_header, auto_row) = table(&out);
    // With a space, clap hands `auto` to the record files: said so.
    let spaced = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--refine",
        "auto",
        path(&estimation),
    ]);
    assert_eq!(spaced.status.code(), Some(2));
    assert!(
        text(&spaced.stderr).contains("write --refine=auto"),
        "{}",
        text(&spaced.stderr)
    );
    for name in ["k", "a1", "a2", "h0", "explained", "refine_stop"] {
        let at = auto_header.iter().position(|h| h == name).unwrap();
        assert_eq!(auto_row[at], row[column(name)], "{name}");
    }

    // The refined values checked by --at give the same check as --refine
    // --check: the same model at the same point on the same record.
    let out = twostage(&[
        "estimate",
        "--model-file",
        path(&model),
        "--at",
        path(&refined),
        "--check",
        path(&estimation),
    ]);
    let (at_header, at_row) = table(&out);
    for name in [
        "k",
        "h0",
        "level_rms",
        "level_fit_percent",
        "check_tail_probability",
        "explained",
    ] {
        let at_column = at_header.iter().position(|h| h == name).unwrap();
        assert_eq!(at_row[at_column], row[column(name)], "{name}");
    }
    // --refine --check reads the search whose best is the refinement (1);
    // --at searches again from the given values and finds the same point.
    let at_ratio: f64 = at_row[at_header
        .iter()
        .position(|h| h == "loss_over_best")
        .unwrap()]
    .parse()
    .unwrap();
    assert_eq!(row[column("loss_over_best")], "1");
    assert!((at_ratio - 1.0).abs() < 1e-9, "{at_ratio}");

    // `models` says what a user must know before estimating: the input is
    // fixed, and which methods the model offers.
    let out = twostage(&["models", "--model-file", path(&model)]);
    let described = text(&out.stdout);
    assert!(
        described
            .contains("input     fixed for every experiment: the pump column of estimation.csv"),
        "{described}"
    );
    assert!(
        described.contains("methods   oe (estimate --method)"),
        "{described}"
    );
}

/// `dir/gain.toml`: the protocol-2 program `dir/gain.py` as a model of one
/// gain `k` in [0, 2], one input and one output, records of `samples`;
/// `source` adds lines under `[source]`.
fn gain_model(dir: &Path, source: &str, samples: usize) -> PathBuf {
    let model = dir.join("gain.toml");
    std::fs::write(
        &model,
        format!(
            "[model]\nname = \"gain\"\n[source]\ncommand = [{:?}, \"gain.py\"]\nprotocol = 2\n\
             {source}[[parameter]]\nname = \"k\"\nprior = {{ dist = \"uniform\", low = 0.0, \
             high = 2.0 }}\n[signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = \
             {samples}\n",
            python()
        ),
    )
    .unwrap();
    model
}

/// A simulator that fails whenever it is asked to run without noise: the
/// check and the refinement fail for each record, say so, and keep its
/// two-stage estimate.
#[test]
fn a_simulator_failing_during_check_and_refine_keeps_the_estimates() {
    let dir = scratch("real-data-failing");
    std::fs::write(
        dir.join("gain.py"),
        format!(
            r#"import sys, random
sys.path.insert(0, {:?})
from twostage_protocol import serve

def simulate(theta, seed, index, noiseless=False, input=None):
    if noiseless:
        raise RuntimeError("the noise-free solver diverged")
    rng = random.Random(seed * 1000003 + index)
    u = [rng.gauss(0, 1) for _ in range(40)]
    return [[v] for v in u], [[theta[0] * v + 0.1 * rng.gauss(0, 1)] for v in u]

serve(simulate)
"#,
            example().join("../../protocol").to_str().unwrap()
        ),
    )
    .unwrap();
    let model = gain_model(&dir, "", 40);
    let estimator = dir.join("gain.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--compress",
        "arx:1,1",
        "--fit",
        "linear",
        "--sims",
        "300",
        "--validate",
        "0",
        "--calibrate",
        "100",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let data = dir.join("data");
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&model),
        "--count",
        "3",
        "--out-dir",
        path(&data),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--check",
        "--refine",
        path(&data.join("data.csv")),
    ]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    // The same failure in every record is said once, the others counted.
    assert_eq!(stderr.matches("--refine failed (").count(), 1, "{stderr}");
    assert_eq!(
        stderr.matches("--check could not simulate").count(),
        1,
        "{stderr}"
    );
    for what in ["--refine", "--check"] {
        assert!(
            stderr.contains(&format!(
                "{what} failed as for experiment 0 in 2 more experiment(s): 1, 2"
            )),
            "{stderr}"
        );
    }
    assert!(
        stderr.contains("the noise-free solver diverged"),
        "{stderr}"
    );
    let (header, row) = table(&out);
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(row[column("refine_stop")], "failed");
    assert_eq!(row[column("explained")], "");
    let k: f64 = row[column("k")].parse().unwrap();
    assert!((0.0..=2.0).contains(&k));
}

/// `simulate --at` with a record per row sends the rows in blocks of the
/// source's batch, each experiment on its own input (`each`), not a
/// request per row; each row's response is its own input's.
#[test]
fn rows_on_inputs_of_their_own_go_to_a_batching_source_in_blocks() {
    let dir = scratch("real-data-rows-in-blocks");
    let calls = dir.join("calls.log");
    std::fs::write(
        dir.join("gain.py"),
        format!(
            r#"import sys
sys.path.insert(0, {:?})
from twostage_protocol import serve

def batch(thetas, seeds, indices, noiseless=False, input=None):
    with open({:?}, "a") as log:
        log.write(f"{{len(thetas)}} {{len(input[0][0]) if input is not None and isinstance(input[0][0], list) else 0}}\n")
    inputs = input if isinstance(input[0][0], list) else [input] * len(thetas)
    return inputs, [[[t[0] * row[0]] for row in u] for t, u in zip(thetas, inputs)]

serve(batch=batch)
"#,
            example().join("../../protocol").to_str().unwrap(),
            calls.to_str().unwrap()
        ),
    )
    .unwrap();
    let model = gain_model(&dir, "batch = 4\n", 5);
    let ids = ["a", "b", "c", "d", "e", "f"];
    let mut records = String::from("experiment,u,y\n");
    let mut estimates = String::from("experiment,k\n");
    for (r, id) in ids.iter().enumerate() {
        for k in 0..5 {
            records.push_str(&format!("{id},{},0\n", (r * 10 + k) as f64 * 0.5));
        }
        estimates.push_str(&format!("{id},{}\n", 0.25 * (r + 1) as f64));
    }
    std::fs::write(dir.join("records.csv"), records).unwrap();
    std::fs::write(dir.join("estimates.csv"), estimates).unwrap();
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&model),
        "--at",
        path(&dir.join("estimates.csv")),
        "--input",
        path(&dir.join("records.csv")),
        "--noiseless",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let rows: Vec<Vec<&str>> = stdout
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 30, "{stdout}");
    for (i, row) in rows.iter().enumerate() {
        let (r, k) = (i / 5, i % 5);
        assert_eq!(row[0], ids[r]);
        let u = (r * 10 + k) as f64 * 0.5;
        let gain = 0.25 * (r + 1) as f64;
        assert_eq!(row[1].parse::<f64>().unwrap().to_bits(), u.to_bits());
        assert_eq!(
            row[2].parse::<f64>().unwrap().to_bits(),
            (gain * u).to_bits()
        );
    }
    // Two requests, of four and two experiments, each input its own.
    let log = std::fs::read_to_string(&calls).unwrap();
    let mut sizes: Vec<&str> = log.lines().collect();
    sizes.sort_unstable();
    assert_eq!(sizes, ["2 1", "4 1"], "{log}");
}
