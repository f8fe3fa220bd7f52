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

/// The control unit draws what `estimate --samples N --seed S` draws: the
/// same numbers for the same seed and record number, from the blob
/// `export` writes; `--without-posterior` leaves the density out and the
/// estimate as it was.
#[test]
fn the_control_unit_draws_what_estimate_draws() {
    let dir = scratch("export_draws");
    let data = dir.join("data");
    let run = |args: &[&str]| {
        let out = twostage(args);
        assert!(out.status.success(), "{args:?}: {}", text(&out.stderr));
        text(&out.stdout)
    };
    run(&[
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
    let file = dir.join("bench.twostage");
    run(&[
        "train",
        "--model",
        "benchmark",
        "--sims",
        "500",
        "--fit",
        "linear",
        "--posterior",
        "2",
        "--validate",
        "0",
        "--calibrate",
        "100",
        "--quiet",
        "--out",
        path(&file),
    ]);
    let records = data.join("data.csv");
    let draws_file = dir.join("draws.csv");
    run(&[
        "estimate",
        "--estimator",
        path(&file),
        "--samples",
        "20",
        "--seed",
        "7",
        "--draws",
        path(&draws_file),
        path(&records),
    ]);
    let blob_path = dir.join("bench.tsrt");
    let said = run(&[
        "export",
        "--estimator",
        path(&file),
        "--out",
        path(&blob_path),
    ]);
    assert!(said.contains("it carries the posterior"), "{said}");
    let blob = std::fs::read(&blob_path).unwrap();
    let runtime = twostage::runtime::Estimator::from_bytes(&blob).unwrap();
    assert!(runtime.has_posterior());

    // The records in the order the file gives them: record k's samples
    // and the CLI's draws of it.
    let table = std::fs::read_to_string(&records).unwrap();
    let mut ids: Vec<String> = Vec::new();
    let mut samples: Vec<Vec<(f64, f64)>> = Vec::new();
    for line in table.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if ids.last().map(String::as_str) != Some(f[0]) {
            ids.push(f[0].to_string());
            samples.push(Vec::new());
        }
        let number = |s: &str| s.parse::<f64>().unwrap();
        samples
            .last_mut()
            .unwrap()
            .push((number(f[1]), number(f[2])));
    }
    let drawn = std::fs::read_to_string(&draws_file).unwrap();
    let mut work = vec![0.0; runtime.workspace_len()];
    for (k, (id, record)) in ids.iter().zip(&samples).enumerate() {
        let expected: Vec<f64> = drawn
            .lines()
            .skip(1)
            .filter(|l| l.split(',').next() == Some(id.as_str()))
            .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(expected.len(), 20, "record {id}");
        let mut stream = twostage::runtime::Stream::new(&runtime, &mut work).unwrap();
        for (u, y) in record {
            stream.push(&[*u], &[*y]).unwrap();
        }
        let (mut theta, mut draws) = ([0.0], [0.0; 20]);
        stream
            .finish_with_draws(&mut theta, &mut [], &mut draws, 7, k as u64)
            .unwrap();
        for (got, want) in draws.iter().zip(&expected) {
            assert!((got - want).abs() <= 1e-9, "record {id}: {got} vs {want}");
        }
    }

    let lean_path = dir.join("lean.tsrt");
    let said = run(&[
        "export",
        "--estimator",
        path(&file),
        "--without-posterior",
        "--out",
        path(&lean_path),
    ]);
    assert!(!said.contains("posterior"), "{said}");
    let lean = std::fs::read(&lean_path).unwrap();
    let lean = twostage::runtime::Estimator::from_bytes(&lean).unwrap();
    assert!(!lean.has_posterior() && lean.n_features() == runtime.n_features());
    let (mut a, mut b) = ([0.0], [0.0]);
    let (inputs, outputs): (Vec<f64>, Vec<f64>) = samples[0].iter().copied().unzip();
    let mut lean_work = vec![0.0; lean.workspace_len()];
    lean.estimate_record(&inputs, &outputs, &mut lean_work, &mut a, &mut [])
        .unwrap();
    runtime
        .estimate_record(&inputs, &outputs, &mut work, &mut b, &mut [])
        .unwrap();
    assert_eq!(a[0].to_bits(), b[0].to_bits());
}
