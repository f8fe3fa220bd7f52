//! The cost of one estimate on one recorded experiment, per method.
//!
//! Groups: `estimate_cost_benchmark` and `estimate_cost_pacejka`. Each
//! method is measured on the same record; the competitors join as the
//! baselines crate provides them.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use twostage::models::{Benchmark, PacejkaCar};
use twostage::{EstimateWorkspace, TwoStage};
use twostage_benches::{config, record};

fn estimate_cost(c: &mut Criterion) {
    let bench = Benchmark::new();
    let estimator = TwoStage::builder(&bench)
        .preset(twostage::paper_benchmark())
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_or_else(|e| panic!("training the benchmark preset: {e}"));
    let data = record(&bench, &[0.5]);
    let mut group = c.benchmark_group("estimate_cost_benchmark");
    let mut work = EstimateWorkspace::new();
    let mut theta = [0.0];
    group.bench_function("ts", |b| {
        b.iter(|| {
            estimator
                .estimate_into(
                    black_box(data.inputs()),
                    black_box(data.outputs()),
                    &mut work,
                    &mut theta,
                )
                .unwrap_or_else(|e| panic!("{e}"));
            black_box(theta[0])
        })
    });
    group.finish();

    let car = PacejkaCar::new();
    let estimator = TwoStage::builder(&car)
        .preset(twostage::paper_pacejka())
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_or_else(|e| panic!("training the car preset: {e}"));
    let data = record(&car, &[-35.0, -1.1]);
    let mut group = c.benchmark_group("estimate_cost_pacejka");
    let mut theta = [0.0; 2];
    group.bench_function("ts", |b| {
        b.iter(|| {
            estimator
                .estimate_into(
                    black_box(data.inputs()),
                    black_box(data.outputs()),
                    &mut work,
                    &mut theta,
                )
                .unwrap_or_else(|e| panic!("{e}"));
            black_box(theta[0])
        })
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = config();
    targets = estimate_cost
}
criterion_main!(benches);
