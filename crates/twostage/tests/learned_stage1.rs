//! A stage 1 that learns (`+learned`), as a user trains,
//! saves and reads it: the network trained with the estimator on the
//! training records, stored in the file, the same bits at any thread
//! count and from a chart file as from simulating it.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::write_chart;
use std::path::PathBuf;

use twostage::compress::Compressor;
use twostage::models::{Benchmark, Simulator, experiment_rng};
use twostage::{ChartFiles, CompressorConfig, Estimator, RecordSource, TwoStage};

fn model() -> Benchmark {
    Benchmark::builder().n_samples(200).build().unwrap()
}

fn trained(model: &Benchmark, compressor: &str, seed: u64) -> Estimator {
    TwoStage::builder(model)
        .compressor(compressor.parse::<CompressorConfig>().unwrap())
        .linear(1e-6)
        .unwrap()
        .simulations(400)
        .calibration(100)
        .validation(200)
        .seed(seed)
        .train()
        .unwrap()
}

#[test]
fn the_network_is_trained_with_the_estimator_and_stored_in_format_7() {
    let model = model();
    let estimator = trained(&model, "arx:2,2+learned:4,4", 3);
    let compressor = estimator.compressor();
    assert!(compressor.learns() && compressor.untrained_summary().is_none());
    // ARX(2, 2)'s four coefficients, then two numbers per last channel.
    assert_eq!(compressor.n_features(), 4 + 8);
    let bytes = estimator.to_bytes().unwrap();
    assert_eq!(bytes[8..12], 7u32.to_le_bytes());
    let back = Estimator::from_bytes(&bytes).unwrap();
    assert_eq!(back, estimator);
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.3], &mut experiment_rng(9, 0), &mut record)
        .unwrap();
    let a = estimator.estimate_record(&record).unwrap();
    let b = back.estimate_record(&record).unwrap();
    assert_eq!(a[0].to_bits(), b[0].to_bits());
    // Without a network the file keeps the version every reader of 6 reads.
    let plain = trained(&model, "arx:2,2", 3);
    assert_eq!(plain.to_bytes().unwrap()[8..12], 6u32.to_le_bytes());
    // The summary is not noise: the learned stage 1 alone estimates the
    // parameter far better than the prior's spread.
    let alone = trained(&model, "learned:4,4", 3);
    let report = alone.validation().unwrap();
    let (lower, upper) = (
        model.spec().prior().lower()[0],
        model.spec().prior().upper()[0],
    );
    let prior_sd = (upper - lower) / 12f64.sqrt();
    assert!(
        report.parameters[0].rmse < 0.5 * prior_sd,
        "RMSE {} against a prior sd of {prior_sd}",
        report.parameters[0].rmse
    );
}

#[test]
fn the_same_seed_gives_the_same_file_at_any_thread_count() {
    let model = model();
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| trained(&model, "learned:4", 5))
    };
    let (one, three) = (on(1), on(3));
    assert!(
        one.compressor() == three.compressor(),
        "the networks differ"
    );
    assert!(one.regressor() == three.regressor(), "stage 2 differs");
    assert!(
        one.to_bytes().unwrap() == three.to_bytes().unwrap(),
        "the files differ"
    );
    assert!(trained(&model, "learned:4", 6).compressor() != one.compressor());
}

fn scratch(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

#[test]
fn a_chart_file_trains_the_same_network_as_simulating_its_records() {
    let model = model();
    let (train, check) = (scratch("learned-train"), scratch("learned-check"));
    write_chart(&model, &train, 300, 7);
    write_chart(&model, &check, 60, 8);
    let spec = model.spec();
    let (chart, other) = (
        ChartFiles::open(&train, spec).unwrap(),
        ChartFiles::open(&check, spec).unwrap(),
    );
    let builder = || {
        TwoStage::builder(&model)
            .compressor("arx:1,1+learned:3".parse::<CompressorConfig>().unwrap())
            .linear(1e-6)
            .unwrap()
            .simulations(300)
            .seed(7)
    };
    let from_files = builder()
        .records(RecordSource::Files {
            training: &chart,
            calibration: Some(&other),
            validation: Some(&other),
        })
        .train()
        .unwrap();
    let simulated = builder().validation(0).calibration(0).train().unwrap();
    assert_eq!(from_files.compressor(), simulated.compressor());
}
