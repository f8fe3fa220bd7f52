//! A C program, compiled here with gcc against the static library and the
//! committed header, estimates fresh benchmark records through the C API
//! and prints the numbers the Rust estimator gives, its posterior's draws
//! included.

#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::path::{Path, PathBuf};
use std::process::Command;

use twostage::TwoStage;
use twostage::fit::{MixtureDensity, MlpParams};
use twostage::models::{
    Benchmark, IoData, SUMMARY_NAMES, Simulator, StreamPurpose, experiment_rng, stream_rng,
};

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

/// The host's input deviations of a one-input record as the runtime's
/// mask (bit k for summary number k).
fn input_mask(host: &twostage::Assessment) -> u64 {
    host.input_deviations
        .iter()
        .map(|d| 1u64 << SUMMARY_NAMES.iter().position(|n| *n == d.quantity).unwrap())
        .fold(0, |m, b| m | b)
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
        .posterior(MixtureDensity::new(MlpParams::new(&[8]).unwrap().check().unwrap(), 2).unwrap())
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
    // One record's input is three times the family's (its RMS and peak
    // beyond any training record's); the flag must say so, by number.
    let loud: Vec<f64> = records[6].input(0).iter().map(|v| 3.0 * v).collect();
    records[6] = IoData::siso(&loud, records[6].output(0)).unwrap();
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

    let (window, every) = (300, 250);
    let output = Command::new(compile(dir.path()))
        .arg(&blob_path)
        .arg(&records_path)
        .args([window.to_string(), every.to_string()])
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
    for (r, record) in records.iter().enumerate() {
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
        // Not the input's shape, which the runtime does not judge yet.
        assert_eq!(
            fields[4] == "1",
            (host.features_outside() || !host.input_deviations.is_empty())
        );
        let distance = host.feature_distance.unwrap();
        assert!((number(5) - distance).abs() <= 1e-9 * distance);
        assert_eq!(
            number(6).to_bits(),
            host.distance_threshold.unwrap().to_bits()
        );
        assert_eq!(fields[7], host.floored_samples.len().to_string());
        // The input's numbers outside the family, bit 4 j + k.
        assert_eq!(
            fields[8],
            input_mask(&host).to_string(),
            "{:?}",
            host.input_deviations
        );
        // The interval, kept inside the prior's box as the host keeps it.
        assert_eq!(fields[9], "0", "ts_interval");
        let (low, high) = twostage::interval_in_box(
            &host.theta,
            host.interval_half_widths().unwrap(),
            estimator.lower(),
            estimator.upper(),
        );
        for (c, host) in [(number(10), low[0]), (number(11), high[0])] {
            assert!((c - host).abs() <= 1e-9, "C bound {c} vs host {host}");
        }
        clipped += usize::from(number(10).to_bits() == estimator.lower()[0].to_bits());
        // The posterior's draws of record r, seed 5: the host's, for a
        // record out of distribution too (its flag is above).
        assert_eq!(fields[12], "0", "ts_stream_finish_draws");
        let mut draws = [0.0; 3];
        estimator
            .sample_record(
                record,
                &mut stream_rng(5, r as u64, StreamPurpose::Posterior),
                &mut draws,
            )
            .unwrap();
        for (k, host) in draws.iter().enumerate() {
            let c = number(13 + k);
            assert!((c - host).abs() <= 1e-9, "draw {k}: C {c} vs host {host}");
        }
    }
    // The record at -0.895 has an interval reaching past the box's -0.9.
    assert!(clipped >= 1, "no interval met the prior's box");
    assert!(estimator.assess(&records[7]).unwrap().out_of_distribution());
    let loud = estimator.assess(&records[6]).unwrap();
    let quantities: Vec<&str> = loud.input_deviations.iter().map(|d| d.quantity).collect();
    assert!(
        quantities.contains(&"RMS") && quantities.contains(&"peak"),
        "{quantities:?}"
    );
    assert_eq!(
        lines.next().unwrap(),
        "-10 a sample is not finite: the record cannot be estimated; reset the stream"
    );
    assert_eq!(lines.next().unwrap(), "after-finish 0");
    assert_eq!(lines.next().unwrap(), "empty -11");
    assert_eq!(lines.next().unwrap(), "short window -16");
    // The window slid over the eight records one after another: each row
    // is the host's estimate of that window alone, flags included.
    let mut long = IoData::zeros(records.len() * n, 1, 1);
    for (i, record) in records.iter().enumerate() {
        long.input_mut(0)[i * n..(i + 1) * n].copy_from_slice(record.input(0));
        long.output_mut(0)[i * n..(i + 1) * n].copy_from_slice(record.output(0));
    }
    let mut rows = 0;
    for line in lines {
        let fields: Vec<&str> = line.split(' ').collect();
        assert_eq!(fields[0], "window", "{line}");
        let end: usize = fields[1].parse().unwrap();
        assert_eq!(end % every, 0);
        let host = estimator
            .assess(&long.window(end.saturating_sub(window), end))
            .unwrap();
        assert_eq!(fields[2], "0", "{line}");
        let theta: f64 = fields[3].parse().unwrap();
        assert!(
            (theta - host.theta[0]).abs() <= 1e-9 * host.theta[0].abs().max(1e-3),
            "window ending at {end}: C {theta} vs Rust {}",
            host.theta[0]
        );
        // The runtime does not judge the input's shape yet: it agrees
        // with the host's features and summary.
        let flagged = host.features_outside() || !host.input_deviations.is_empty();
        assert_eq!(fields[4] == "1", flagged, "{line}");
        assert_eq!(fields[5], input_mask(&host).to_string(), "{line}");
        rows += 1;
    }
    assert_eq!(rows, records.len() * n / every);
}
