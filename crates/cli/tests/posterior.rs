//! `train --posterior` and `estimate --samples`: draws from the
//! estimator's posterior, as a scientist with a simulator asks for them.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{ok, path, scratch, text, twostage};

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
    assert_eq!(lines[0], "experiment,draw,out_of_distribution,theta");
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

    // A record far outside the training records has its draws written
    // and flagged.
    let odd = dir.join("odd.csv");
    let odd_text: String = std::fs::read_to_string(&records)
        .unwrap()
        .lines()
        .enumerate()
        .filter_map(|(i, l)| {
            let f: Vec<&str> = l.split(',').collect();
            match i {
                0 => Some("u,y\n".to_string()),
                _ if f[0] == lines[1].split(',').next().unwrap() => {
                    let y: f64 = f[2].parse().unwrap();
                    Some(format!("{},{}\n", f[1], 50.0 * y))
                }
                _ => None,
            }
        })
        .collect();
    std::fs::write(&odd, odd_text).unwrap();
    let odd_draws = dir.join("odd-draws.csv");
    ok(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "5",
        "--draws",
        path(&odd_draws),
        path(&odd),
    ]);
    let flagged = std::fs::read_to_string(&odd_draws).unwrap();
    assert!(
        flagged
            .lines()
            .skip(1)
            .all(|l| l.split(',').nth(2) == Some("true")),
        "{flagged}"
    );

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

    // --at tests values against each record's posterior: the records' own
    // truth (a row per experiment) and one far value for all.
    let truth = data.join("truth.csv");
    let tested = ok(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "2000",
        "--at",
        path(&truth),
        path(&records),
    ]);
    let header: Vec<&str> = tested.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (level, inside, mean, sd) = (
        column("region_level"),
        column("in_region_90"),
        column("theta_posterior_mean"),
        column("theta_posterior_sd"),
    );
    for row in tested.lines().skip(1) {
        let fields: Vec<&str> = row.split(',').collect();
        let l: f64 = fields[level].parse().unwrap();
        assert!((0.0..=1.0).contains(&l), "{row}");
        assert_eq!(fields[inside], (l <= 0.9).to_string(), "{row}");
    }
    let far = dir.join("far.csv");
    std::fs::write(&far, "theta\n0.899\n").unwrap();
    let tested = ok(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "2000",
        "--at",
        path(&far),
        path(&records),
    ]);
    let mut checked = 0;
    for row in tested.lines().skip(1) {
        let fields: Vec<&str> = row.split(',').collect();
        let (m, s): (f64, f64) = (fields[mean].parse().unwrap(), fields[sd].parse().unwrap());
        let l: f64 = fields[level].parse().unwrap();
        // A value many sds from the posterior's mean is in no region a
        // user would quote; one within half an sd is in its central half.
        if (0.899 - m).abs() > 4.0 * s {
            assert!(l > 0.99 && fields[inside] == "false", "{row}");
            checked += 1;
        } else if (0.899 - m).abs() < 0.5 * s {
            assert!(l < 0.5, "{row}");
            checked += 1;
        }
    }
    assert!(checked > 0, "{tested}");
    let without_draws = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--at",
        path(&far),
        path(&records),
    ]);
    assert!(without_draws.contains("add --samples N"), "{without_draws}");
    let outside = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "10",
        "--at",
        path(&far),
        "--allow-outside-prior",
        path(&records),
    ]);
    assert!(
        outside.contains("--allow-outside-prior goes with --at --check"),
        "{outside}"
    );
    let without_check = refused(&[
        "estimate",
        "--model",
        "benchmark",
        "--at",
        path(&far),
        path(&records),
    ]);
    assert!(
        without_check.contains("--check") && without_check.contains("--samples"),
        "{without_check}"
    );
    // simulate --at the draws --band 90: each experiment's band over its
    // draws' simulations on its own input, its mean the mean of the same
    // simulations written one by one; the record's samples mostly inside.
    let draws_file = dir.join("band-draws.csv");
    ok(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "200",
        "--draws",
        path(&draws_file),
        path(&records),
    ]);
    let simulate = |band: bool| {
        let mut args = vec![
            "simulate",
            "--model",
            "benchmark",
            "--at",
            path(&draws_file),
            "--input",
            path(&records),
        ];
        if band {
            args.extend(["--band", "90"]);
        }
        let out = twostage(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        (text(&out.stdout), text(&out.stderr))
    };
    let (band, said) = simulate(true);
    let (each, _) = simulate(false);
    let mut lines = band.lines();
    assert_eq!(
        lines.next(),
        Some("experiment,u,y_mean,y_low,y_high"),
        "{band}"
    );
    let band_rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let each_rows: Vec<Vec<f64>> = each
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let n = band_rows.len() / 3;
    assert_eq!(each_rows.len(), 200 * band_rows.len());
    for (k, b) in band_rows.iter().enumerate().step_by(97) {
        let (experiment, sample) = (k / n, k % n);
        let values: Vec<f64> = (0..200)
            .map(|d| each_rows[(experiment * 200 + d) * n + sample][2])
            .collect();
        let mean = values.iter().sum::<f64>() / 200.0;
        assert!(
            (b[2] - mean).abs() < 1e-9 * (1.0 + mean.abs()),
            "{b:?} {mean}"
        );
        assert!(b[3] <= b[2] && b[2] <= b[4], "{b:?}");
    }
    let inside: Vec<f64> = said
        .lines()
        .filter_map(|l| {
            l.split("% of samples inside the band")
                .next()?
                .rsplit(", ")
                .next()?
                .parse()
                .ok()
        })
        .collect();
    assert_eq!(inside.len(), 3, "{said}");
    assert!(inside.iter().all(|p| (75.0..=99.5).contains(p)), "{said}");
    let bad = refused(&[
        "simulate",
        "--model",
        "benchmark",
        "--at",
        path(&draws_file),
        "--input",
        path(&records),
        "--band",
        "100",
    ]);
    assert!(bad.contains("between 0 and 100"), "{bad}");

    // train says the posterior's calibration on its validation records.
    let trained = twostage(&[
        "train",
        "--model",
        "benchmark",
        "--sims",
        "300",
        "--fit",
        "linear",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--posterior",
        "2",
        "--out",
        path(&dir.join("said.twostage")),
    ]);
    assert!(trained.status.success());
    let said = text(&trained.stderr);
    assert!(
        said.contains("posterior (200 draws of each of the 100 records)")
            && said.contains("its ranks among the draws"),
        "{said}"
    );

    // validate scores the posterior's calibration on its fresh records;
    // the JSON has it under `posterior`; an estimator without one has none.
    let validated = ok(&["validate", "--estimator", path(&with), "--sims", "300"]);
    let line = validated
        .lines()
        .find(|l| l.starts_with("posterior (200 draws of each of the 300 records)"))
        .unwrap_or_else(|| panic!("{validated}"));
    assert!(line.contains("90% 0."), "{line}");
    assert!(
        validated.contains("its ranks among the draws"),
        "{validated}"
    );
    let json = ok(&[
        "validate",
        "--estimator",
        path(&with),
        "--sims",
        "300",
        "--format",
        "json",
    ]);
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(value["posterior"]["records"], 300);
    let plain = ok(&["validate", "--estimator", path(&without), "--sims", "300"]);
    assert!(!plain.contains("posterior ("), "{plain}");
    let other = dir.join("other.csv");
    std::fs::write(&other, "alpha\n0.1\n").unwrap();
    let wrong = refused(&[
        "estimate",
        "--estimator",
        path(&with),
        "--samples",
        "10",
        "--at",
        path(&other),
        path(&records),
    ]);
    assert!(
        wrong.contains("other.csv") && wrong.contains("theta"),
        "{wrong}"
    );
}
