//! docs/any-experiment.md, step by step: one estimator of the two tanks'
//! multisine family estimates ten realizations of one plant (checked and
//! refined), flags an input outside the family with the reason, follows a
//! long record window by window, and exports its family to the runtime.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::PathBuf;

use common::{path, scratch, text, twostage};

fn family_file() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/examples/tanks/tanks_multisine.toml")
}

/// The rows of an estimate CSV as (header, rows of fields).
fn table(csv: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let mut lines = csv.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

/// Simulate the plant of the guide (k 1.2, a1 0.9, a2 0.8, h0 4) from
/// `model` into `out`, experiment `experiment`'s streams.
fn simulate_plant(model: &std::path::Path, experiment: u64, out: &std::path::Path) {
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(model),
        "--theta",
        "1.2,0.9,0.8,4",
        "--experiment",
        &experiment.to_string(),
        "--out",
        path(out),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

fn column(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

#[test]
fn one_estimator_reads_every_experiment_of_its_family() {
    let dir = scratch("any-experiment");
    let model = family_file();
    let estimator = dir.join("family.tsest");
    // 1. The family, and an estimator of it (smaller than the guide's).
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--compress",
        "arx:4,4",
        "--fit",
        "mlp:16",
        "--sims",
        "1000",
        "--calibrate",
        "500",
        "--validate",
        "500",
        "--seed",
        "1",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let shown = text(&twostage(&["inspect", path(&estimator)]).stdout);
    assert!(
        shown.contains("input family of its 1000 held-out records"),
        "{shown}"
    );
    assert!(shown.contains("pump: mean 2.2 to 2.2, RMS 0.4"), "{shown}");

    // 2. Ten realizations of one plant, checked and refined.
    let truth = [("k", 1.2), ("a1", 0.9), ("a2", 0.8), ("h0", 4.0)];
    let runs: Vec<PathBuf> = (0..10)
        .map(|i| {
            let run = dir.join(format!("run-{i}.csv"));
            simulate_plant(&model, i, &run);
            run
        })
        .collect();
    let mut args = vec![
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--check",
        "--refine=auto",
    ];
    args.extend(runs.iter().map(|r| path(r)));
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (header, rows) = table(&text(&out.stdout));
    assert_eq!(rows.len(), 10);
    let in_family = column(&header, "input_in_family");
    let explained = column(&header, "explained");
    assert!(rows.iter().all(|r| r[in_family] == "true"), "{rows:?}");
    let explained = rows.iter().filter(|r| r[explained] == "true").count();
    assert!(explained >= 8, "{explained} of 10 explained");
    let mut covered = 0;
    for (name, value) in truth {
        let (lo, hi) = (
            column(&header, &format!("{name}_lo")),
            column(&header, &format!("{name}_hi")),
        );
        for r in &rows {
            let (l, h): (f64, f64) = (r[lo].parse().unwrap(), r[hi].parse().unwrap());
            covered += usize::from(l <= value && value <= h);
        }
    }
    // The guide's estimator covers 37 of 40; a smaller one a few less.
    assert!(covered >= 28, "{covered} of 40 intervals cover the truth");

    // 3. An input outside the family: estimated, flagged with the reason.
    let source = std::fs::read_to_string(&model).unwrap();
    let loud_model = dir.join("loud.toml");
    std::fs::write(&loud_model, source.replace("rms = [0.4, 0.8]", "rms = 1.2")).unwrap();
    let loud = dir.join("loud.csv");
    simulate_plant(&loud_model, 0, &loud);
    let out = twostage(&["estimate", "--estimator", path(&estimator), path(&loud)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let warning = text(&out.stderr);
    assert!(
        warning.contains("input pump: RMS 1.200 above the training records' 0.4"),
        "{warning}"
    );
    let (header, rows) = table(&text(&out.stdout));
    assert_eq!(rows[0][column(&header, "input_in_family")], "false");

    // 4. A long record, window by window.
    let long_model = dir.join("long.toml");
    std::fs::write(
        &long_model,
        source.replace("samples = 400", "samples = 1600"),
    )
    .unwrap();
    let long = dir.join("long.csv");
    simulate_plant(&long_model, 0, &long);
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--window",
        "400",
        "--every",
        "200",
        path(&long),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (header, rows) = table(&text(&out.stdout));
    let ends: Vec<&str> = rows
        .iter()
        .map(|r| r[column(&header, "window_end")].as_str())
        .collect();
    assert_eq!(ends, ["400", "600", "800", "1000", "1200", "1400", "1600"]);

    // 5. The runtime's blob carries the family.
    let blob = dir.join("family.tsrt");
    let out = twostage(&[
        "export",
        "--estimator",
        path(&estimator),
        "--to",
        "runtime",
        "--out",
        path(&blob),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let bytes = std::fs::read(&blob).unwrap();
    let runtime = twostage::runtime::Estimator::from_bytes(&bytes).unwrap();
    assert!(runtime.has_input_family());
    assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 2);
}

/// A simulated CSV's numbers, column by column after the header.
fn numbers(csv: &str) -> Vec<Vec<f64>> {
    csv.lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn the_car_written_as_equations_is_the_built_in_car() {
    let dir = scratch("car-equations");
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/examples/car");
    // The same sampled steering for both (the chicane's samples, which
    // both read by their cubic between samples).
    let mut steering = String::from("delta\n");
    for k in 0..500 {
        let t = f64::from(k) * 0.02;
        let v = if (1.0..=9.0).contains(&t) {
            0.2 * (std::f64::consts::TAU * (t - 1.0) / 4.0).sin()
                * (std::f64::consts::PI * (t - 1.0) / 8.0).sin().powi(2)
        } else {
            0.0
        };
        steering.push_str(&format!("{v:e}\n"));
    }
    std::fs::write(dir.join("steering.csv"), steering).unwrap();
    let given = "[input]\nsignal = \"fixed\"\nfile = \"steering.csv\"";
    let equations = std::fs::read_to_string(examples.join("car_equations.toml"))
        .unwrap()
        .replace("[input]\nsignal = \"chicane\"\namplitude = 0.2", given);
    assert!(equations.contains("steering.csv"));
    std::fs::write(dir.join("equations.toml"), equations).unwrap();
    std::fs::write(
        dir.join("builtin.toml"),
        format!("[model]\nname = \"car\"\n[source]\nbuiltin = \"pacejka\"\n{given}\n"),
    )
    .unwrap();
    let run = |file: &str, theta: &str| {
        let out = twostage(&[
            "simulate",
            "--model-file",
            path(&dir.join(file)),
            "--theta",
            theta,
            "--noiseless",
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        numbers(&text(&out.stdout))
    };
    for theta in ["-42,-1.2", "-35,-1.1", "-28,-0.99"] {
        let (a, b) = (run("equations.toml", theta), run("builtin.toml", theta));
        assert_eq!(a.len(), 500);
        let peak = a.iter().fold(0.0f64, |m, row| m.max(row[1].abs()));
        assert!(
            peak > 5.0,
            "{theta}: a chicane's lateral acceleration, {peak}"
        );
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                (x[1] - y[1]).abs() <= 1e-9 * y[1].abs().max(1.0),
                "{theta}, sample {k}: equations {} against built-in {}",
                x[1],
                y[1]
            );
        }
    }
    // The drifting tire: the same car, pK1 growing by 10 over the drive;
    // at its start it is the constant car, at its end it is not.
    let drifting = std::fs::read_to_string(examples.join("car_drifting_tire.toml"))
        .unwrap()
        .replace("samples = 30000", "samples = 3000");
    std::fs::write(dir.join("drifting.toml"), &drifting).unwrap();
    std::fs::write(
        dir.join("constant.toml"),
        drifting.replace("k1 = \"pK1 + (10 / 600) * t\"", "k1 = \"pK1\""),
    )
    .unwrap();
    let (drift, constant) = (
        run("drifting.toml", "-40,-1.1"),
        run("constant.toml", "-40,-1.1"),
    );
    let gap = |k: usize| (drift[k][1] - constant[k][1]).abs();
    assert!(gap(5) < 1e-3 * constant[5][1].abs().max(0.1), "{}", gap(5));
    let late = (2500..3000).map(gap).fold(0.0f64, f64::max);
    assert!(late > 0.01, "{late}");
}

/// Section 7: the car's manoeuvre family trains from its file's first
/// preset, whose stage 1 is `+summary` (smaller than the guide's),
/// `inspect` names the stage 1, a chicane record is
/// estimated inside the prior and not flagged by its input, and the
/// estimator exports to the runtime.
#[test]
fn the_car_on_manoeuvres_trains_with_each_records_summary() {
    let dir = scratch("car-manoeuvres");
    let model = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/car/car_manoeuvres.toml");
    let estimator = dir.join("car-manoeuvres.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--fit",
        "mlp:5",
        "--sims",
        "400",
        "--calibrate",
        "200",
        "--validate",
        "100",
        "--seed",
        "1",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let inspected = twostage(&["inspect", path(&estimator)]);
    let inspected = text(&inspected.stdout);
    assert!(
        inspected.contains("mean, RMS, peak and mean frequency"),
        "{inspected}"
    );
    let chicane = dir.join("chicane.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--theta",
        "-35,-1.1",
        "--out",
        path(&chicane),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = twostage(&["estimate", "--estimator", path(&estimator), path(&chicane)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (header, rows) = table(&text(&out.stdout));
    let pk1: f64 = rows[0][column(&header, "pK1")].parse().unwrap();
    assert!((-42.83..=-27.32).contains(&pk1), "{pk1}");
    let flag = &rows[0][column(&header, "out_of_distribution")];
    assert_eq!(flag, "false", "{header:?} {rows:?}");
    let out = twostage(&[
        "export",
        "--estimator",
        path(&estimator),
        "--to",
        "runtime",
        "--out",
        path(&dir.join("car.tsrt")),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // Format version 3: the summary's flag, which a runtime of before
    // refuses rather than misreads.
    let blob = std::fs::read(dir.join("car.tsrt")).unwrap();
    assert_eq!(&blob[..8], b"TSRT\x03\0\0\0");
}
