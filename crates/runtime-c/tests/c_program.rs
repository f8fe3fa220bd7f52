//! A C program, compiled here with gcc against the static library and the
//! committed header, estimates fresh benchmark records through the C API
//! and prints the numbers the Rust estimator gives.

#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::path::{Path, PathBuf};
use std::process::Command;

use twostage::TwoStage;
use twostage::models::{Benchmark, IoData, Simulator, experiment_rng};

/// Build `libtwostage_rt.a` (release, in its own target directory, so that
/// this test's cargo does not wait on the one running it).
fn static_library() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let target = manifest.join("../../target/c-api");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .args([
            "build",
            "--release",
            "--lib",
            "-p",
            "twostage-runtime-c",
            "--target-dir",
        ])
        .arg(&target)
        .status()
        .unwrap();
    assert!(status.success(), "building the static library failed");
    target.join("release/libtwostage_rt.a")
}

fn compile(dir: &Path) -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let program = dir.join("estimate_records");
    let output = Command::new("gcc")
        .args(["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(manifest.join("include"))
        .arg(manifest.join("tests/c/estimate_records.c"))
        .arg(static_library())
        // What a Rust static library with std needs from the C library
        // (`rustc --print native-static-libs`).
        .args([
            "-lgcc_s",
            "-lutil",
            "-lrt",
            "-lpthread",
            "-lm",
            "-ldl",
            "-lc",
            "-o",
        ])
        .arg(&program)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "gcc failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    program
}

#[test]
fn a_c_program_prints_the_rust_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let model = Benchmark::new();
    let estimator = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .simulations(400)
        .validation(0)
        .calibration(200)
        .seed(21)
        .train()
        .unwrap();
    let blob_path = dir.path().join("benchmark.tsrt");
    std::fs::write(&blob_path, estimator.to_runtime().unwrap()).unwrap();

    // Fresh records; the last one has its output scaled tenfold, which no
    // benchmark system produces (the flag must say so), and one is cut
    // too short to estimate.
    let n = model.spec().n_samples();
    let mut records: Vec<IoData> = (0..8u32)
        .map(|i| {
            let mut record = model.spec().new_record();
            // The first at the prior box's edge, where intervals are cut.
            let theta = if i == 0 {
                -0.895
            } else {
                -0.8 + 0.2 * f64::from(i)
            };
            model
                .simulate(&[theta], &mut experiment_rng(31, u64::from(i)), &mut record)
                .unwrap();
            record
        })
        .collect();
    let alien: Vec<f64> = records[7].output(0).iter().map(|v| 10.0 * v).collect();
    records[7] = IoData::siso(records[7].input(0), &alien).unwrap();
    let mut text = format!("{} {n} 1 1\n", records.len() + 1);
    for record in &records {
        for (u, y) in record.input(0).iter().zip(record.output(0)) {
            text.push_str(&format!("{u:e} {y:e}\n"));
        }
    }
    // Nine samples of a constant record: too short for ARX(5, 5) and
    // padded to n with NaN, which the stream refuses.
    for t in 0..n {
        text.push_str(if t < 9 { "1 1\n" } else { "nan nan\n" });
    }
    let records_path = dir.path().join("records.txt");
    std::fs::write(&records_path, text).unwrap();

    let output = Command::new(compile(dir.path()))
        .arg(&blob_path)
        .arg(&records_path)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8(output.stdout).unwrap();
    let mut lines = stdout.lines();
    assert_eq!(
        lines.next().unwrap(),
        "damaged -4 the blob's checksum does not match: it was damaged; export it again"
    );
    let mut clipped = 0;
    for record in &records {
        let fields: Vec<&str> = lines.next().unwrap().split(' ').collect();
        assert_eq!(fields[0], "0", "{fields:?}");
        let number = |k: usize| fields[k].parse::<f64>().unwrap();
        let host = estimator.assess(record).unwrap();
        let theta = number(1);
        assert!(
            (theta - host.theta[0]).abs() <= 1e-9 * host.theta[0].abs().max(1e-3),
            "C {theta} vs Rust {}",
            host.theta[0]
        );
        let width = host.interval_half_widths().unwrap()[0];
        assert!((number(2) - width).abs() <= 1e-9 * width);
        assert_eq!(fields[3], "2", "adaptive intervals");
        assert_eq!(fields[4] == "1", host.out_of_distribution());
        let distance = host.feature_distance.unwrap();
        assert!((number(5) - distance).abs() <= 1e-9 * distance);
        assert_eq!(
            number(6).to_bits(),
            host.distance_threshold.unwrap().to_bits()
        );
        assert_eq!(fields[7], host.floored_samples.len().to_string());
        // The interval, kept inside the prior's box as the host keeps it.
        assert_eq!(fields[8], "0", "ts_interval");
        let (low, high) = twostage::interval_in_box(
            &host.theta,
            host.interval_half_widths().unwrap(),
            estimator.lower(),
            estimator.upper(),
        );
        for (c, host) in [(number(9), low[0]), (number(10), high[0])] {
            assert!((c - host).abs() <= 1e-9, "C bound {c} vs host {host}");
        }
        clipped += usize::from(number(9).to_bits() == estimator.lower()[0].to_bits());
    }
    // The record at -0.895 has an interval reaching past the box's -0.9.
    assert!(clipped >= 1, "no interval met the prior's box");
    assert!(estimator.assess(&records[7]).unwrap().out_of_distribution());
    assert_eq!(
        lines.next().unwrap(),
        "-10 a sample is not finite: the record cannot be estimated; reset the stream"
    );
    assert_eq!(lines.next().unwrap(), "after-finish 0");
    assert_eq!(lines.next().unwrap(), "empty -11");
}
