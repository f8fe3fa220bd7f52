//! The offline side: compression as N grows, one simulation of each model,
//! and training the two paper presets.
//!
//! Groups: `compress` (ARX(5, 5) at N = 250 .. 16000, the cost must grow
//! linearly), `simulate`, `certify` (the betting certificate of r squared
//! errors), `train` (the two paper presets, and ten Adam epochs of the
//! [64, 64] network a large chart gets: 5000 records of 40 features).

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use twostage::TwoStage;
use twostage::compress::{Arx, Compressor, Workspace};
use twostage::fit::Regressor;
use twostage::models::{Benchmark, PacejkaCar, Simulator, experiment_rng};
use twostage_benches::{config, record, slow_config};

fn compress(c: &mut Criterion) {
    let arx = Arx::new(5, 5).unwrap_or_else(|e| panic!("{e}"));
    let mut group = c.benchmark_group("compress");
    for n in [250usize, 1000, 4000, 16000] {
        let model = Benchmark::builder()
            .n_samples(n)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        let data = record(&model, &[0.5]);
        let mut work = Workspace::new();
        let mut alpha = [0.0; 10];
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("arx5_5_fast", n), &data, |b, data| {
            b.iter(|| {
                arx.compress_fast_into(
                    black_box(data.inputs()),
                    black_box(data.outputs()),
                    &mut work,
                    &mut alpha,
                )
                .unwrap_or_else(|e| panic!("{e}"));
                black_box(alpha[0])
            })
        });
        group.bench_with_input(BenchmarkId::new("arx5_5", n), &data, |b, data| {
            b.iter(|| {
                arx.compress_into(
                    black_box(data.inputs()),
                    black_box(data.outputs()),
                    &mut work,
                    &mut alpha,
                )
                .unwrap_or_else(|e| panic!("{e}"));
                black_box(alpha[0])
            })
        });
    }
    group.finish();
}

fn simulate(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulate");
    let bench = Benchmark::new();
    let mut out = bench.spec().new_record();
    group.bench_function("benchmark_n1000", |b| {
        b.iter(|| {
            bench
                .simulate(black_box(&[0.5]), &mut experiment_rng(1, 0), &mut out)
                .unwrap_or_else(|e| panic!("{e}"));
            black_box(out.output(0)[999])
        })
    });
    let car = PacejkaCar::new();
    let mut out = car.spec().new_record();
    group.bench_function("pacejka_chicane", |b| {
        b.iter(|| {
            car.simulate(
                black_box(&[-35.0, -1.1]),
                &mut experiment_rng(1, 0),
                &mut out,
            )
            .unwrap_or_else(|e| panic!("{e}"));
            black_box(out.output(0)[499])
        })
    });
    group.finish();
}

fn certify(c: &mut Criterion) {
    let mut group = c.benchmark_group("certify");
    for r in [1000usize, 100_000] {
        // Squared errors of the benchmark preset's size (MSE 7e-4).
        let errors: Vec<f64> = (0..r)
            .map(|i| 1.4e-3 * ((i * 7919) % 1000) as f64 / 1000.0)
            .collect();
        group.throughput(Throughput::Elements(r as u64));
        group.bench_with_input(BenchmarkId::new("betting", r), &errors, |b, errors| {
            b.iter(|| {
                twostage::validate::BettingBound::from_squared_errors(black_box(errors), 3.24, 1e-3)
                    .unwrap_or_else(|e| panic!("{e}"))
            })
        });
    }
    group.finish();
}

fn train(c: &mut Criterion) {
    let mut group = c.benchmark_group("train");
    let bench = Benchmark::new();
    group.bench_function("paper_benchmark", |b| {
        b.iter(|| {
            TwoStage::builder(&bench)
                .preset(twostage::paper_benchmark())
                .validation(0)
                .calibration(0)
                .train()
                .unwrap_or_else(|e| panic!("{e}"))
        })
    });
    let car = PacejkaCar::new();
    group.bench_function("paper_pacejka", |b| {
        b.iter(|| {
            TwoStage::builder(&car)
                .preset(twostage::paper_pacejka())
                .validation(0)
                .calibration(0)
                .train()
                .unwrap_or_else(|e| panic!("{e}"))
        })
    });
    // The network sized for a large chart trains by Adam:
    // its epochs are what the search's final fit spends its time on.
    let (x, t) = adam_problem(5000, 40, 4);
    let adam = twostage::fit::MlpParams::new(&[64, 64])
        .and_then(|p| {
            p.restarts(1)
                .seed(1)
                .trainer(twostage::fit::Trainer::Adam {
                    learning_rate: 1e-3,
                    batch_size: 64,
                    epochs: 10,
                })
                .check()
        })
        .unwrap_or_else(|e| panic!("{e}"));
    group.bench_function("adam_10_epochs_64x64", |b| {
        b.iter(|| {
            adam.fit(x.view(), t.view())
                .unwrap_or_else(|e| panic!("{e}"))
        })
    });
    group.finish();
}

/// `rows` records of `n` features in [-1, 1] and `q` smooth targets of
/// them, from a fixed stream.
fn adam_problem(rows: usize, n: usize, q: usize) -> (ndarray::Array2<f64>, ndarray::Array2<f64>) {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut uniform = move || {
        // xorshift64: any fixed stream serves.
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let x = ndarray::Array2::from_shape_fn((rows, n), |_| uniform());
    let t = ndarray::Array2::from_shape_fn((rows, q), |(i, k)| {
        (x[[i, k]] * x[[i, k + 1]] + x[[i, k + 2]]).sin()
    });
    (x, t)
}

criterion_group! {
    name = fast;
    config = config();
    targets = compress, simulate, certify
}
criterion_group! {
    name = slow;
    config = slow_config();
    targets = train
}
criterion_main!(fast, slow);
