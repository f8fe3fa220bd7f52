//! docs/any-experiment.md, "A family shaped like a measured input": the
//! Duffing-type oscillator's blocks, driven by a multisine whose lines
//! fall at the top of its band and measured with an offset the model file
//! does not give exactly, are outside a family of equal lines and inside
//! one shaped like a block (`like`), its offset one number or a range.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};

use common::{path, scratch, text, train_small, twostage};

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/duffing")
        .join(name)
}

/// Train on `model` (small: the family's flags need no accurate
/// estimator) and estimate `blocks` with `extra` arguments: what
/// `estimate` says on stderr.
fn said_of_blocks(dir: &Path, model: &Path, blocks: &[PathBuf], extra: &[&str]) -> String {
    let estimator = train_small(model);
    let mut args = vec!["estimate", "--estimator", path(&estimator)];
    args.extend(extra);
    args.extend(blocks.iter().map(|b| path(b)));
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let rows = text(&out.stdout).lines().count();
    assert_eq!(rows, blocks.len() + 1, "{dir:?}");
    text(&out.stderr)
}

/// The lines of `said` that hold `words`.
fn lines_with<'a>(said: &'a str, words: &str) -> Vec<&'a str> {
    said.lines().filter(|l| l.contains(words)).collect()
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
    // its shape is far from the family's: one line for each flag names
    // the blocks of every file.
    let equal = write(
        "equal.toml",
        shaped.replace("like = { file = \"block-0.csv\", column = \"u\" }", ""),
    );
    let said = said_of_blocks(&dir, &equal, &blocks, &[]);
    let inputs = lines_with(&said, "their inputs lie outside the family");
    let shapes = lines_with(&said, "their input shapes");
    assert_eq!((inputs.len(), shapes.len()), (1, 1), "{said}");
    for (i, block) in blocks.iter().enumerate() {
        let named = format!("block-{i} ({})", block.display());
        assert!(
            inputs[0].contains(&named) && shapes[0].contains(&named),
            "{said}"
        );
        let why = format!("experiment block-{i}: input u: mean frequency");
        assert!(inputs[0].contains(&why), "{said}");
    }
    assert_eq!(said.lines().count(), 2, "{said}");
    // Shaped like block 0: no block is flagged, the offset drawn or fixed
    // 1.3% above the blocks' (a fraction of a percent of their RMS).
    let fixed_offset = write(
        "fixed-offset.toml",
        shaped.replace("offset = [0.0058, 0.0064]", "offset = 0.00612"),
    );
    let shaped = write("shaped.toml", shaped.clone());
    for model in [&shaped, &fixed_offset] {
        let said = said_of_blocks(&dir, model, &blocks, &[]);
        assert!(said.is_empty(), "{model:?}: {said}");
    }
    // Refined through the model, which leaves the plant's quadratic
    // stiffness out: each note once, naming the blocks of every file.
    let said = said_of_blocks(
        &dir,
        &shaped,
        &blocks,
        &["--model-file", path(&shaped), "--check", "--refine=auto"],
    );
    let auto = lines_with(&said, "--refine=auto: the check explains");
    assert_eq!(auto.len(), 1, "{said}");
    assert!(auto[0].contains("two-stage estimates in 4 files"), "{said}");
    let inexact = lines_with(&said, "the model does not make these records exactly");
    assert_eq!(inexact.len(), 1, "{said}");
    for (i, block) in blocks.iter().enumerate() {
        let named = format!("block-{i} ({})", block.display());
        assert!(inexact[0].contains(&named), "{said}");
    }
    assert!(said.lines().count() <= 3, "{said}");
}
