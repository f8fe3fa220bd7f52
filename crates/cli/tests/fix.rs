//! `train --fix NAME=VALUE`: a parameter held at a value, said by
//! `inspect`, held by the estimate's check and refinement, and refused
//! with the model's names where it is not one of them.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{path, scratch, text, twostage};

#[test]
fn a_fixed_parameter_is_said_held_and_refined_around() {
    let dir = scratch("fix");
    let file = dir.join("held.tsest");
    let train = |fix: &str| {
        twostage(&[
            "train",
            "--model",
            "pacejka",
            "--fix",
            fix,
            "--sims",
            "600",
            "--validate",
            "300",
            "--calibrate",
            "300",
            "--out",
            path(&file),
        ])
    };
    let out = train("pK2=-1.05");
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("holding pK2 = -1.05 (not estimated)"));
    let out = twostage(&["inspect", path(&file)]);
    let printed = text(&out.stdout);
    assert!(printed.contains("format version 10"), "{printed}");
    assert!(
        printed.contains("fixed       pK2 = -1.05 (held while training, not estimated)"),
        "{printed}"
    );
    assert!(!printed.contains("parameter   pK2"), "{printed}");

    // The runtime's blob estimates pK1 and says so.
    let blob = dir.join("held.blob");
    let out = twostage(&["export", "--estimator", path(&file), "--out", path(&blob)]);
    assert!(
        text(&out.stdout).contains("it estimates pK1; pK2 = -1.05 held while training"),
        "{}",
        text(&out.stdout)
    );

    // A record of the car at pK2 = -1.05: the check and the refinement
    // run the car with pK2 held, and the refined pK1 is near its truth.
    let record = dir.join("record.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--theta",
        "-35,-1.05",
        "--seed",
        "4",
        "--out",
        path(&record),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&file),
        "--refine",
        "--check",
        path(&record),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let printed = text(&out.stdout);
    let mut lines = printed.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        &header[..4],
        ["experiment", "pK1", "pK1_lo", "pK1_hi"],
        "{printed}"
    );
    let column = |name: &str| row[header.iter().position(|h| *h == name).unwrap()];
    let (estimate, lo, hi): (f64, f64, f64) = (
        column("pK1").parse().unwrap(),
        column("pK1_lo").parse().unwrap(),
        column("pK1_hi").parse().unwrap(),
    );
    assert!(
        lo <= -35.0 && -35.0 <= hi && (estimate + 35.0).abs() < 1.5,
        "{printed}"
    );
    assert_eq!(column("model_consistent"), "true", "{printed}");

    // Names and values the model does not take, refused as usage.
    for (fix, said) in [
        ("mass=1500", "its parameters are pK1, pK2"),
        ("pK2", "give NAME=VALUE"),
        ("pK2=0.31", "[-1.22, -0.98]"),
    ] {
        let out = train(fix);
        assert_eq!(out.status.code(), Some(2), "{fix}: {}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains(said),
            "{fix}: {}",
            text(&out.stderr)
        );
    }
}

/// The refined pK1 of `estimate --refine --check` with `extra`, its
/// interval, and the table's header.
fn refined_pk1(estimator: &str, record: &str, extra: &[&str]) -> (f64, f64, f64, Vec<String>) {
    let mut args = vec!["estimate", "--estimator", estimator, "--refine", "--check"];
    args.extend(extra);
    args.push(record);
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let printed = text(&out.stdout);
    let mut lines = printed.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| -> f64 {
        row[header.iter().position(|h| h == name).unwrap()]
            .parse()
            .unwrap()
    };
    (column("pK1"), column("pK1_lo"), column("pK1_hi"), header)
}

/// `estimate --fix` holds a parameter of an estimator trained without it
/// held: the rows are of the others, and the refinement through the
/// model with the value held ends where the refinement of an estimator
/// trained with it held ends (the same loss, searched from other starts).
#[test]
fn a_value_held_at_estimate_time_is_refined_around_as_one_held_in_training() {
    let dir = scratch("fix_at_estimate");
    let train = |fix: &[&str], out: &str| {
        let mut args = vec![
            "train",
            "--model",
            "pacejka",
            "--sims",
            "600",
            "--validate",
            "0",
            "--calibrate",
            "300",
            "--out",
            out,
        ];
        args.extend(fix);
        let done = twostage(&args);
        assert!(done.status.success(), "{}", text(&done.stderr));
    };
    let (whole, held) = (dir.join("whole.tsest"), dir.join("held.tsest"));
    train(&[], path(&whole));
    train(&["--fix", "pK2=-1.05"], path(&held));
    let record = dir.join("record.csv");
    let out = twostage(&[
        "simulate",
        "--model",
        "pacejka",
        "--theta",
        "-35,-1.05",
        "--seed",
        "4",
        "--out",
        path(&record),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let (at_estimate, lo, hi, header) =
        refined_pk1(path(&whole), path(&record), &["--fix", "pK2=-1.05"]);
    assert!(!header.iter().any(|h| h.starts_with("pK2")), "{header:?}");
    assert!(lo <= -35.0 && -35.0 <= hi, "{lo} {hi}");
    let (in_training, ..) = refined_pk1(path(&held), path(&record), &[]);
    assert!(
        (at_estimate - in_training).abs() < 1e-3 * in_training.abs(),
        "{at_estimate} against {in_training}"
    );
    // Not holding it, the refinement searches both.
    let (_, _, _, both) = refined_pk1(path(&whole), path(&record), &[]);
    assert!(both.iter().any(|h| h == "pK2"), "{both:?}");

    // What it refuses, and why.
    for (fix, said) in [
        (&["--fix", "mass=1500"][..], "its parameters are pK1, pK2"),
        (&["--fix", "pK2=0.31"][..], "[-1.22, -0.98]"),
        (
            &["--fix", "pK1=-35", "--fix", "pK2=-1.05"][..],
            "every parameter is fixed",
        ),
    ] {
        let mut args = vec!["estimate", "--estimator", path(&whole)];
        args.extend(fix);
        args.push(path(&record));
        let out = twostage(&args);
        assert_eq!(out.status.code(), Some(2), "{fix:?}: {}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains(said),
            "{fix:?}: {}",
            text(&out.stderr)
        );
    }
}
