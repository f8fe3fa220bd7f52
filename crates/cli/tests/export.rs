//! `twostage export --to runtime`: the blob the microcontroller runtime
//! reads, and the structures it refuses.

mod common;

use common::{path, scratch, text, twostage};
use twostage::Estimator;
use twostage::models::{Benchmark, Simulator, experiment_rng};

fn train(file: &std::path::Path, compress: &str) {
    let out = twostage(&[
        "train",
        "--model",
        "benchmark",
        "--sims",
        "300",
        "--compress",
        compress,
        "--fit",
        "mlp:4",
        "--validate",
        "0",
        "--calibrate",
        "150",
        "--quiet",
        "--out",
        path(file),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

#[test]
fn an_exported_estimator_streams_to_the_estimates_of_its_file() {
    let dir = scratch("export");
    let file = dir.join("bench.tsest");
    train(&file, "arx:3,3");
    let blob_path = dir.join("bench.tsrt");
    let out = twostage(&[
        "export",
        "--estimator",
        path(&file),
        "--to",
        "runtime",
        "--out",
        path(&blob_path),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let said = text(&out.stdout);
    let blob = std::fs::read(&blob_path).expect("the blob was written");
    assert!(said.contains(&format!("({} bytes)", blob.len())), "{said}");
    let runtime = twostage::runtime::Estimator::from_bytes(&blob).expect("the blob reads back");
    assert!(
        said.contains(&format!("workspace of {} numbers", runtime.workspace_len())),
        "{said}"
    );

    let host = Estimator::load(&file).expect("the file loads");
    let model = Benchmark::new();
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.3], &mut experiment_rng(8, 0), &mut record)
        .expect("a benchmark record");
    let mut work = vec![0.0; runtime.workspace_len()];
    let (mut theta, mut widths) = ([0.0], [0.0]);
    runtime
        .estimate_record(
            record.input(0),
            record.output(0),
            &mut work,
            &mut theta,
            &mut widths,
        )
        .expect("the runtime estimates");
    let expected = host
        .estimate(record.input(0), record.output(0))
        .expect("the host estimates");
    assert!((theta[0] - expected[0]).abs() <= 1e-9 * expected[0].abs());
}

#[test]
fn a_structure_the_runtime_cannot_stream_is_refused_with_what_to_do() {
    let dir = scratch("export-narx");
    let file = dir.join("narx.tsest");
    train(&file, "narx:2,2,2");
    let blob = dir.join("narx.tsrt");
    let out = twostage(&["export", "--estimator", path(&file), "--out", path(&blob)]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("cannot be exported to the runtime") && err.contains("--compress arx:NA,NB"),
        "{err}"
    );
    assert!(!blob.exists(), "nothing is written for a refused estimator");
    // A learned stage 1 after ARX coefficients exports (format version
    // 4); a network alone is refused, saying what the runtime takes.
    let learned = dir.join("learned.tsest");
    train(&learned, "arx:2,2+learned:3");
    let shown = twostage(&["inspect", path(&learned)]);
    assert!(shown.status.success(), "{}", text(&shown.stderr));
    assert!(
        text(&shown.stdout)
            .contains("a learned summary (3 channels, kernel 5, stride 2; 33 weights"),
        "{}",
        text(&shown.stdout)
    );
    let out = twostage(&[
        "export",
        "--estimator",
        path(&learned),
        "--out",
        path(&blob),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let bytes = std::fs::read(&blob).expect("the blob is written");
    let runtime = twostage::runtime::Estimator::from_bytes(&bytes).expect("the runtime reads it");
    assert!(runtime.has_learned_summary() && bytes[4] == 4);
    std::fs::remove_file(&blob).expect("the blob is removed");
    let alone = dir.join("alone.tsest");
    train(&alone, "learned:3");
    let out = twostage(&["export", "--estimator", path(&alone), "--out", path(&blob)]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("after ARX coefficients") && err.contains("arx:NA,NB+learned"),
        "{err}"
    );
    assert!(!blob.exists());
    let missing = dir.join("missing.tsest");
    let out = twostage(&[
        "export",
        "--estimator",
        path(&missing),
        "--out",
        path(&blob),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("missing.tsest"),
        "{}",
        text(&out.stderr)
    );
}
