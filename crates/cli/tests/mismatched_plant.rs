//! Records of a plant the model misses part of (issue 72, items 0 and
//! 4): a first-order lag fitted to a plant with a cubic term.
//!
//! - With `--joint`, each record at its own input level, each record's own
//!   best fit moves with its level: the joint fit says that the scatter
//!   between the records, not their noise, sets the widths, and each
//!   record's interval then holds the joint estimate.
//! - With `--refine --check`, the check finds that the model does not make
//!   the record even at its best fit: the refined estimate is that best
//!   fit itself, not the posterior mean near it (which pulls a parameter
//!   on a bound inside, at a cost in fit the noise does not explain).

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use common::{field, path, rows, scratch, simulate_beside, text, train_small, twostage};

const MODEL: &str = r#"
[model]
name = "lag"
description = "a first-order lag"

[[parameter]]
name = "a"
prior = { dist = "uniform", low = 0.5, high = 3.0 }

[[parameter]]
name = "b"
prior = { dist = "uniform", low = 0.5, high = 3.0 }

[signals]
inputs = ["u"]
outputs = ["y"]
samples = 400
sample_time = 0.05

[input]
signal = "multisine"
band = [0.0, 2.0]
rms = [0.2, 2.0]

[equations]
states = [{ name = "x", initial = "0", derivative = "b * u - a * x" }]
outputs = { y = "x" }

[noise]
output_sd = 0.01
"#;

/// `estimate` of the records with `extra`: its table and its stderr.
fn estimate(
    estimator: &Path,
    model: &Path,
    records: &[String],
    extra: &[&str],
) -> (String, String) {
    let mut args = vec![
        "estimate",
        "--estimator",
        path(estimator),
        "--model-file",
        path(model),
        "--refine",
    ];
    args.extend(extra);
    args.extend(records.iter().map(String::as_str));
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    (text(&out.stdout), text(&out.stderr))
}

#[test]
fn a_mismatched_plants_records_hold_the_joint_estimate_with_their_scatter() {
    let dir = scratch("mismatched_plant_joint");
    let model = dir.join("lag.toml");
    std::fs::write(&model, MODEL).unwrap();
    let plant = dir.join("plant.toml");
    std::fs::write(
        &plant,
        MODEL.replace("\"b * u - a * x\"", "\"b * u - a * x - 0.3 * x^3\""),
    )
    .unwrap();
    let records: Vec<String> = (0..6)
        .map(|i| simulate_beside(&plant, "1.5,1.5", i))
        .collect();
    let estimator = train_small(&model);

    let (alone, _) = estimate(&estimator, &model, &records, &[]);
    let (together, said) = estimate(&estimator, &model, &records, &["--joint"]);
    let (alone, together) = (rows(&alone), rows(&together));
    assert_eq!(together.len(), alone.len() + 1);
    let (last, joint) = together.last().unwrap();
    assert_eq!(last, "joint");
    let at = field(joint, "a");
    let covers = |row: &[(String, f64)]| field(row, "a_lo") <= at && at <= field(row, "a_hi");
    let (mut own, mut widened) = (0, 0);
    for ((id, own_row), (same, joint_row)) in alone.iter().zip(&together) {
        assert_eq!(id, same);
        // The estimates are the records' own; only their intervals grow.
        assert_eq!(
            field(own_row, "a").to_bits(),
            field(joint_row, "a").to_bits()
        );
        assert!(
            field(joint_row, "a_hi") - field(joint_row, "a_lo")
                > field(own_row, "a_hi") - field(own_row, "a_lo")
        );
        own += usize::from(covers(own_row));
        widened += usize::from(covers(joint_row));
    }
    assert!(
        own <= 3 && widened >= 5,
        "own intervals cover the joint a {own} times, widened {widened}: {said}"
    );
    let note = said
        .lines()
        .find(|l| l.contains("scatter beyond their noise"))
        .unwrap_or_else(|| panic!("{said}"));
    assert!(
        note.contains("(sd between records against a record's own: a "),
        "{note}"
    );
    assert!(note.contains("the model's mismatch with the plant, not the noise, sets these widths"));
    // Records whose estimates disagree are said to be possibly of another
    // plant, or of one the model misses part of: here, the latter.
    let warning = said
        .lines()
        .find(|l| l.contains("lie beyond their intervals"))
        .unwrap_or_else(|| panic!("{said}"));
    assert!(
        warning.contains("or the model may miss part of the plant"),
        "{warning}"
    );
}

/// A cubic coefficient whose prior ends below the plant's: its best fit
/// sits on the box's bound, where the posterior mean near it would lie
/// inside. The model does not make the record, so the refined estimate
/// is the best fit itself and the check explains it.
#[test]
fn on_a_record_the_model_does_not_make_the_refined_estimate_is_the_best_fit() {
    let dir = scratch("mismatched_plant_best_fit");
    let with_cubic = MODEL
        .replace("\"b * u - a * x\"", "\"b * u - a * x - c * x^3\"")
        .replace(
            "[signals]",
            "[[parameter]]\nname = \"c\"\nprior = { dist = \"uniform\", low = 0.0, high = 0.05 }\n\n[signals]",
        );
    let model = dir.join("cubic.toml");
    std::fs::write(&model, &with_cubic).unwrap();
    let plant = dir.join("plant.toml");
    std::fs::write(&plant, with_cubic.replace("- c * x^3", "- 0.3 * x^3")).unwrap();
    let record = simulate_beside(&plant, "1.5,1.5,0", 3);
    let estimator = train_small(&model);
    let (table, said) = estimate(&estimator, &model, &[record], &["--check"]);
    let rows = rows(&table);
    let [(_, row)] = rows.as_slice() else {
        panic!("{table}")
    };
    // On the bound, at the best fit's loss, and explained by its check.
    assert_eq!(field(row, "c").to_bits(), 0.05f64.to_bits(), "{table}");
    assert_eq!(
        field(row, "loss_over_best").to_bits(),
        1.0f64.to_bits(),
        "{table}"
    );
    let mut lines = table.lines().map(|l| l.split(',').collect::<Vec<_>>());
    let header = lines.next().unwrap();
    let explained = header.iter().position(|h| *h == "explained").unwrap();
    assert_eq!(lines.next().unwrap()[explained], "true", "{table}");
    assert!(field(row, "check_best_fit_tail_probability") <= 0.01);
    assert!(
        said.contains("the refined estimate is the model's best fit itself"),
        "{said}"
    );
}
