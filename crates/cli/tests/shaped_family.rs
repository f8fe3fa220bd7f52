//! docs/any-experiment.md, "A family shaped like a measured input": the
//! Duffing-type oscillator's blocks, driven by a multisine whose lines
//! fall at the top of its band and measured with an offset the model file
//! does not give exactly, are outside a family of equal lines and inside
//! one shaped like a block (`like`), its offset one number or a range.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};

use common::{path, scratch, text, twostage};

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/duffing")
        .join(name)
}

/// Train on `model` (small: the family's flags need no accurate
/// estimator) and estimate `blocks`: per block, the warnings that name it.
fn warnings_per_block(dir: &Path, model: &Path, blocks: &[PathBuf]) -> Vec<Vec<String>> {
    let estimator = model.with_extension("tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(model),
        "--compress",
        "arx:2,2",
        "--fit",
        "linear",
        "--sims",
        "400",
        "--calibrate",
        "200",
        "--validate",
        "200",
        "--seed",
        "3",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let mut args = vec!["estimate", "--estimator", path(&estimator)];
    args.extend(blocks.iter().map(|b| path(b)));
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert_eq!(
        text(&out.stdout).lines().count(),
        blocks.len() + 1,
        "{dir:?}"
    );
    (0..blocks.len())
        .map(|i| {
            stderr
                .lines()
                .filter(|l| l.contains(&format!("experiment block-{i}:")))
                .map(String::from)
                .collect()
        })
        .collect()
}

#[test]
fn a_family_shaped_like_a_measured_block_holds_every_block() {
    let dir = scratch("shaped-family");
    let plant = dir.join("plant.toml");
    std::fs::copy(example("plant.toml"), &plant).unwrap();
    let blocks: Vec<PathBuf> = (0..4)
        .map(|i| {
            let block = dir.join(format!("block-{i}.csv"));
            let out = twostage(&[
                "simulate",
                "--model-file",
                path(&plant),
                "--theta",
                "40,150000,4000000,150000",
                "--experiment",
                &i.to_string(),
                "--out",
                path(&block),
            ]);
            assert!(out.status.success(), "{}", text(&out.stderr));
            block
        })
        .collect();
    let shaped = std::fs::read_to_string(example("duffing.toml")).unwrap();
    assert!(shaped.contains("like = { file = \"block-0.csv\", column = \"u\" }"));
    assert!(shaped.contains("offset = [0.0058, 0.0064]"));
    let write = |name: &str, text: String| {
        let model = dir.join(name);
        std::fs::write(&model, text).unwrap();
        model
    };
    // Equal lines: every block is below the family's mean frequency, and
    // its shape is far from the family's.
    let equal = write(
        "equal.toml",
        shaped.replace("like = { file = \"block-0.csv\", column = \"u\" }", ""),
    );
    for (i, said) in warnings_per_block(&dir, &equal, &blocks).iter().enumerate() {
        assert!(
            said.iter()
                .any(|l| l.contains("mean frequency") && l.contains("below")),
            "block {i}: {said:?}"
        );
        assert!(
            said.iter().any(|l| l.contains("input shape")),
            "block {i}: {said:?}"
        );
    }
    // Shaped like block 0: no block is flagged, the offset drawn or fixed
    // 1.3% above the blocks' (a fraction of a percent of their RMS).
    let fixed_offset = write(
        "fixed-offset.toml",
        shaped.replace("offset = [0.0058, 0.0064]", "offset = 0.00612"),
    );
    for model in [write("shaped.toml", shaped.clone()), fixed_offset] {
        for (i, said) in warnings_per_block(&dir, &model, &blocks).iter().enumerate() {
            assert!(said.is_empty(), "{model:?}, block {i}: {said:?}");
        }
    }
}
