//! `train --posterior` and `estimate --samples`: draws from the
//! estimator's posterior, as a scientist with a simulator asks for them.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{path, scratch, text, twostage};

fn ok(args: &[&str]) -> String {
    let out = twostage(args);
    assert!(out.status.success(), "{args:?}: {}", text(&out.stderr));
    text(&out.stdout)
}

fn refused(args: &[&str]) -> String {
    let out = twostage(args);
    assert!(!out.status.success(), "{args:?} was not refused");
    text(&out.stderr)
}

/// The draws' file has the asked count per record, every draw inside the
/// prior's box, the table their mean and sd per parameter; the same seed
/// writes the same bytes, another seed other draws; what cannot draw is
/// refused with what to do.
#[test]
fn draws_are_written_per_record_seeded_and_refused_where_none_can_be_made() {
    let dir = scratch("posterior_draws");
    let data = dir.join("data");
    ok(&[
        "simulate",
        "--model",
        "benchmark",
        "--count",
        "3",
        "--seed",
        "5",
        "--out-dir",
        path(&data),
    ]);
    let records = data.join("data.csv");
    let with = dir.join("with.twostage");
    let without = dir.join("without.twostage");
    let train = |file: &std::path::Path, posterior: bool| {
        let mut args = vec![
            "train",
            "--model",
            "benchmark",
            "--sims",
            "600",
            "--fit",
            "linear",
            "--validate",
            "0",
            "--calibrate",
            "0",
            "--quiet",
            "--out",
            path(file),
        ];
        if posterior {
            args.extend(["--posterior", "2"]);
        }
        ok(&args);
    };
    train(&with, true);
    train(&without, false);
    let inspected = ok(&["inspect", path(&with)]);
    assert!(
        inspected.contains("format version 9")
            && inspected.contains("posterior   mixture of 2 full-covariance Gaussians"),
        "{inspected}"
    );
    let draws = |seed: &str, file: &std::path::Path| {
        let table = ok(&[
            "estimate",
            "--estimator",
            path(&with),
            "--samples",
            "50",
            "--seed",
            seed,
            "--draws",
            path(file),
            path(&records),
        ]);
        (table, std::fs::read_to_string(file).unwrap())
    };
    let (table, first) = draws("3", &dir.join("a.csv"));
    let header = table.lines().next().unwrap();
    assert!(
        header.ends_with("theta_posterior_mean,theta_posterior_sd"),
        "{header}"
    );
    let lines: Vec<&str> = first.lines().collect();
    assert_eq!(lines[0], "experiment,draw,theta");
    assert_eq!(lines.len(), 1 + 3 * 50);
    for line in &lines[1..] {
        let v: f64 = line.rsplit(',').next().unwrap().parse().unwrap();
        assert!((-0.9..=0.9).contains(&v), "{line}");
    }
    // The table's mean is the draws' mean of its record.
    let record_mean = |id: &str| {
        let values: Vec<f64> = lines[1..]
            .iter()
            .filter(|l| l.split(',').next() == Some(id))
            .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
            .collect();
        values.iter().sum::<f64>() / values.len() as f64
    };
    let row = table.lines().nth(1).unwrap();
    let fields: Vec<&str> = row.split(',').collect();
    let said: f64 = fields[fields.len() - 2].parse().unwrap();
    assert!((said - record_mean(fields[0])).abs() < 1e-12, "{said}");
    assert_eq!(draws("3", &dir.join("b.csv")).1, first);
    assert_ne!(draws("4", &dir.join("c.csv")).1, first);

    // --correlation reads the draws' correlations (none for one
    // parameter), and is refused where nothing gives one.
    let correlated = ok(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "20",
        "--correlation",
        path(&records),
    ]);
    assert_eq!(correlated.lines().next(), table.lines().next());
    let alone = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--correlation",
        path(&records),
    ]);
    assert!(alone.contains("--refine, --joint and --samples"), "{alone}");
    let zero = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "0",
        path(&records),
    ]);
    assert!(
        zero.contains("--samples") && zero.contains("at least 1"),
        "{zero}"
    );
    let none = refused(&[
        "estimate",
        "--estimator",
        path(&without),
        "--samples",
        "10",
        path(&records),
    ]);
    assert!(none.contains("--posterior K"), "{none}");
    let classic = refused(&[
        "estimate",
        "--model",
        "benchmark",
        "--method",
        "ekf",
        "--samples",
        "10",
        path(&records),
    ]);
    assert!(classic.contains("only a trained estimator"), "{classic}");
    let huge = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "100000000000000",
        path(&records),
    ]);
    assert!(
        huge.contains("--samples") && huge.contains("draws take"),
        "{huge}"
    );
}
