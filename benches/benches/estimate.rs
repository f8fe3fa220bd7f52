//! The cost of one estimate on one recorded experiment, per method.
//!
//! Groups: `estimate_cost_benchmark` (ts, ekf, ukf, pf1000, pem1, pem5,
//! pem10, bayes, ii5) and `estimate_cost_pacejka` (ts, pf500, pem5), every
//! method on the same record of its group.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use twostage::compress::Arx;
use twostage::models::{Benchmark, IoData, PacejkaCar};
use twostage::{EstimateWorkspace, Estimator, TwoStage};
use twostage_baselines::{
    BayesBenchmark, BenchmarkParticles, BenchmarkPredictor, CarParticles, CarPredictor,
    IndirectInference, InitialCovariance, KalmanEstimator, ParticleFilter, PredictionError,
    RecordEstimator,
};
use twostage_benches::{config, record, slow_config};

fn bench_ts(
    c: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    estimator: &Estimator,
    data: &IoData,
) {
    let mut work = EstimateWorkspace::new();
    let mut theta = vec![0.0; estimator.param_names().len()];
    c.bench_function("ts", |b| {
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
}

fn bench_method(
    c: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    id: &str,
    method: &dyn RecordEstimator,
    data: &IoData,
) {
    c.bench_function(id, |b| {
        b.iter(|| {
            black_box(
                method
                    .estimate(black_box(data))
                    .unwrap_or_else(|e| panic!("{id}: {e}"))
                    .theta[0],
            )
        })
    });
}

fn benchmark_costs(c: &mut Criterion) {
    let bench = Benchmark::new();
    let estimator = TwoStage::builder(&bench)
        .preset(twostage::paper_benchmark())
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_or_else(|e| panic!("training the benchmark preset: {e}"));
    let data = record(&bench, &[0.5]);
    let mut group = c.benchmark_group("estimate_cost_benchmark");
    bench_ts(&mut group, &estimator, &data);
    bench_method(
        &mut group,
        "ekf",
        &KalmanEstimator::ekf(InitialCovariance::Eq6),
        &data,
    );
    bench_method(
        &mut group,
        "ukf",
        &KalmanEstimator::ukf(InitialCovariance::Eq6),
        &data,
    );
    let predictor = || BenchmarkPredictor::new().unwrap_or_else(|e| panic!("{e}"));
    bench_method(
        &mut group,
        "pem1",
        &PredictionError::new(predictor(), 1),
        &data,
    );
    bench_method(
        &mut group,
        "pem5",
        &PredictionError::new(predictor(), 5),
        &data,
    );
    bench_method(
        &mut group,
        "pem10",
        &PredictionError::new(predictor(), 10),
        &data,
    );
    group.finish();
    let mut group = c.benchmark_group("estimate_cost_benchmark");
    group.sample_size(10);
    let particles = BenchmarkParticles::new().unwrap_or_else(|e| panic!("{e}"));
    bench_method(
        &mut group,
        "pf1000",
        &ParticleFilter::new(particles, 1000),
        &data,
    );
    bench_method(&mut group, "bayes", &BayesBenchmark::default(), &data);
    // Indirect inference through the preset's ARX(5, 5): S = 10, W from 200
    // simulations (built once, outside the timing, as for a deployed method).
    let ii5 = IndirectInference::new(
        bench.clone(),
        Arx::new(5, 5).unwrap_or_else(|e| panic!("{e}")),
        5,
    )
    .build()
    .unwrap_or_else(|e| panic!("indirect inference: {e}"));
    bench_method(&mut group, "ii5", &ii5, &data);
    group.finish();
}

fn pacejka_costs(c: &mut Criterion) {
    let car = PacejkaCar::new();
    let estimator = TwoStage::builder(&car)
        .preset(twostage::paper_pacejka())
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_or_else(|e| panic!("training the car preset: {e}"));
    let data = record(&car, &[-35.0, -1.1]);
    let mut group = c.benchmark_group("estimate_cost_pacejka");
    bench_ts(&mut group, &estimator, &data);
    group.finish();
    let mut group = c.benchmark_group("estimate_cost_pacejka");
    group.sample_size(10);
    bench_method(
        &mut group,
        "pf500",
        &ParticleFilter::new(CarParticles::new(), 500),
        &data,
    );
    bench_method(
        &mut group,
        "pem5",
        &PredictionError::new(CarPredictor::new(), 5),
        &data,
    );
    group.finish();
}

criterion_group! {
    name = benches;
    config = config();
    targets = benchmark_costs
}
criterion_group! {
    name = car;
    config = slow_config();
    targets = pacejka_costs
}
criterion_main!(benches, car);
