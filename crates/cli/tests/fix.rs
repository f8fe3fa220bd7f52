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
