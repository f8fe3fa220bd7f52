//! The estimator files that the presets and every way of training write,
//! frozen by their hashes: a refactor of the training path must leave them
//! byte for byte as they were (and estimates the same bits). When a change
//! is meant to change them, run with `TWOSTAGE_PRINT_HASHES=1`, check why
//! each differs, and update the table in the same commit.
//!
//! The hashes are of files written on x86-64 with AVX2 and FMA (faer
//! dispatches its kernels by processor, up to x86-v3 as the workspace
//! builds it): another processor family may round differently, so the
//! table is checked only where it was measured.

// Each test binary uses its own share of the common helpers.
#[allow(dead_code)]
mod common;

use std::path::Path;
use std::process::Command;

use common::{scratch, text};

/// A model file with a built-in source, changed, and a preset of its own.
const MODEL_FILE: &str = r#"
[model]
name = "frozen"
[source]
builtin = "benchmark"
[[parameter]]
name = "theta"
prior = { dist = "truncnormal", mu = 0.1, sigma = 0.4, low = -0.9, high = 0.9 }
[signals]
inputs = ["u"]
outputs = ["y"]
samples = 300
[[preset]]
name = "small"
compress = "arx:3,3"
fit = "mlp:6"
sims = 300
"#;

/// 64-bit FNV-1a of a file's bytes.
fn hash_file(file: &Path) -> u64 {
    let bytes = std::fs::read(file).expect("the estimator file was written");
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |hash, &b| {
        (hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Run `twostage` in `dir` and insist that it succeeds.
fn run_in(dir: &Path, args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_twostage"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the twostage binary runs");
    assert!(
        out.status.success(),
        "twostage {}: {}",
        args.join(" "),
        text(&out.stderr)
    );
}

/// Whether this processor is where the table was measured.
fn measured_here() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Train each case into its own file and compare every hash with the table.
fn check(cases: &[(&str, &[&str], u64)], dir: &Path) {
    let print = std::env::var_os("TWOSTAGE_PRINT_HASHES").is_some();
    let mut differ = Vec::new();
    for (name, args, expected) in cases {
        let out = format!("{name}.tsest");
        let mut all: Vec<&str> = args.to_vec();
        all.extend(["--out", &out, "--quiet"]);
        run_in(dir, &all);
        let hash = hash_file(&dir.join(&out));
        if print {
            println!("(\"{name}\", 0x{hash:016x}),");
        }
        if hash != *expected {
            differ.push(format!(
                "{name}: 0x{hash:016x}, the table says 0x{expected:016x}"
            ));
        }
    }
    if measured_here() && !print {
        assert!(
            differ.is_empty(),
            "estimator files changed:\n{}",
            differ.join("\n")
        );
    }
}

#[test]
fn the_presets_write_the_files_they_always_wrote() {
    let dir = scratch("frozen-presets");
    let small = ["--sims", "300", "--validate", "200", "--calibrate", "200"];
    let with = |head: &'static [&'static str]| -> Vec<&'static str> {
        head.iter().chain(small.iter()).copied().collect()
    };
    let bench_paper = with(&["train", "--model", "benchmark"]);
    let bench_recommended = with(&["train", "--model", "benchmark", "--preset", "recommended"]);
    let car_paper = with(&["train", "--model", "pacejka"]);
    let car_recommended = with(&["train", "--model", "pacejka", "--preset", "recommended"]);
    // Every file below changed on purpose when the networks' tanh became
    // the project's own (within 3 ulps of glibc's, so every weight moved in
    // its last bits; the accuracy is unchanged).
    check(
        &[
            // Every default of the command line: m, seed, validation, calibration, alpha.
            // It changed on purpose when the default validation began to
            // grow until its certificate is within 1.2 times the observed
            // error; its first round of 1000 records alone writes the file
            // it wrote before.
            (
                "benchmark-defaults",
                &["train", "--model", "benchmark"],
                0x035457e9e4ce81e8,
            ),
            (
                "benchmark-defaults-validation-fixed",
                &["train", "--model", "benchmark", "--validate", "1000"],
                0x9fee6264cc7ab1a9,
            ),
            ("benchmark-paper", &bench_paper, 0xe9eb76f02a22e072),
            (
                "benchmark-recommended",
                &bench_recommended,
                0x2739774f3dc840d0,
            ),
            // The car's two targets share one hidden layer, whose
            // Gauss-Newton products come from its structure: the same
            // numbers summed in another order than the Jacobian's.
            ("pacejka-paper", &car_paper, 0x1f8a3776cb46dc6f),
            ("pacejka-recommended", &car_recommended, 0x1740c26ecabe29d1),
        ],
        &dir,
    );
}

#[test]
fn every_source_writes_the_file_it_always_wrote() {
    let dir = scratch("frozen-sources");
    std::fs::write(dir.join("model.toml"), MODEL_FILE).unwrap();
    run_in(
        &dir,
        &[
            "simulate",
            "--model",
            "benchmark",
            "--count",
            "200",
            "--seed",
            "4",
            "--out-dir",
            "chart",
        ],
    );
    for i in 0..3 {
        let shard = format!("{i}/3");
        run_in(
            &dir,
            &[
                "simulate",
                "--model-file",
                "model.toml",
                "--count",
                "240",
                "--validate",
                "60",
                "--calibrate",
                "120",
                "--seed",
                "5",
                "--shard",
                &shard,
                "--out",
                "shards",
            ],
        );
    }
    let chart = [
        "train",
        "--model",
        "benchmark",
        "--chart",
        "chart",
        "--validate",
        "40",
        "--calibrate",
        "40",
        "--compress",
        "arx:2,2",
        "--fit",
        "mlp:4",
    ];
    let model_file = [
        "train",
        "--model-file",
        "model.toml",
        "--validate",
        "100",
        "--calibrate",
        "100",
    ];
    let shards = [
        "train",
        "--model-file",
        "model.toml",
        "--chart",
        "shards/shard-*",
        "--compress",
        "arx:3,3",
        "--fit",
        "mlp:6",
    ];
    let auto = [
        "train",
        "--model-file",
        "model.toml",
        "--auto",
        "--budget-sims",
        "200",
        "--validate",
        "50",
        "--calibrate",
        "50",
    ];
    // Changed on purpose with the input family, as the presets' files above.
    check(
        &[
            ("chart-csv", &chart, 0xbc5fb25100b0b479),
            ("model-file-preset", &model_file, 0x341d326088ea10ed),
            ("shards", &shards, 0x229c930a9e4b8f37),
            // Changed on purpose by issue 27: round 3 averages the winner's
            // restarts, and here the average wins (was 0xcd51098186e891d5).
            ("auto-sims", &auto, 0x0bf668263f4229ad),
        ],
        &dir,
    );
}
