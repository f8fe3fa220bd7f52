//! The microcontroller runtime on this machine: the cost of one pushed
//! sample (`runtime_push`, per sample) and of the final solve, network,
//! intervals and envelope (`runtime_finish`), for both presets of both
//! models, and the same of a window that slides over the record's last
//! quarter (`runtime_window_push`, per sample of a full window, and
//! `runtime_window_finish`), and of the car's estimator whose stage 1 ends
//! in a learned summary network (docs/embedded.md puts them beside the
//! Cortex-M4's instruction counts); and the posterior's draws through a
//! stream (`runtime_draws`: a finish with 1000 draws, per draw) beside
//! the host's own (`host_draws`: `Estimator::sample_into`, stage 1
//! included). The estimators are trained on fewer simulations than the
//! presets say: the cost depends on the structure, not on m.

use std::hint::black_box;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use twostage::fit::MixtureDensity;
use twostage::models::{Benchmark, IoData, PacejkaCar, Simulator, StreamPurpose, stream_rng};
use twostage::runtime::{Estimator, Stream};
use twostage::{Preset, TwoStage};
use twostage_benches::{config, record};

struct Case {
    name: &'static str,
    blob: Vec<u8>,
    inputs: Vec<f64>,
    outputs: Vec<f64>,
}

fn case(name: &'static str, model: &dyn Simulator, preset: Preset, theta: &[f64]) -> Case {
    let estimator = TwoStage::builder(model)
        .preset(preset)
        .simulations(1000)
        .validation(0)
        .calibration(300)
        .train()
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    case_of(name, model, &estimator, theta)
}

/// The car's estimator of a family, its stage 1 as `compress` says (a
/// learned summary network after the ARX coefficients and the summary,
/// or the car linearized) and `ensemble:10`, trained on the built-in
/// car's records: the cost is the structure's.
fn family_case(name: &'static str, compress: &str, theta: &[f64]) -> Case {
    let model = PacejkaCar::new();
    let compressor: twostage::compress::CompressorConfig =
        compress.parse().unwrap_or_else(|e| panic!("{e}"));
    let estimator = TwoStage::builder(&model)
        .compressor(compressor)
        .regressor("ensemble:10".parse().unwrap_or_else(|e| panic!("{e}")))
        .simulations(300)
        .validation(0)
        .calibration(200)
        .train()
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    case_of(name, &model, &estimator, theta)
}

fn case_of(
    name: &'static str,
    model: &dyn Simulator,
    estimator: &twostage::Estimator,
    theta: &[f64],
) -> Case {
    let blob = estimator
        .to_runtime()
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let data: IoData = record(model, theta);
    Case {
        name,
        blob,
        inputs: data.inputs().iter().copied().collect(),
        outputs: data.outputs().iter().copied().collect(),
    }
}

fn runtime(c: &mut Criterion) {
    let cases = [
        case(
            "benchmark_paper",
            &Benchmark::new(),
            twostage::paper_benchmark(),
            &[0.4],
        ),
        case(
            "benchmark_recommended",
            &Benchmark::new(),
            twostage::recommended_benchmark(),
            &[0.4],
        ),
        case(
            "car_paper",
            &PacejkaCar::new(),
            twostage::paper_pacejka(),
            &[-25.0, -1.0],
        ),
        case(
            "car_recommended",
            &PacejkaCar::new(),
            twostage::recommended_pacejka(),
            &[-25.0, -1.0],
        ),
        family_case("car_learned", "arx:2,2+summary+learned", &[-25.0, -1.0]),
        family_case("car_linearized", "linearized", &[-25.0, -1.0]),
        family_case("car_linearized1", "linearized:1", &[-25.0, -1.0]),
    ];
    for case in &cases {
        let estimator = Estimator::from_bytes(&case.blob).unwrap_or_else(|e| panic!("{e}"));
        let (nu, ny) = (estimator.n_inputs(), estimator.n_outputs());
        let samples = case.outputs.len() / ny;
        let q = estimator.n_parameters();
        let mut work = vec![0.0; estimator.workspace_len()];
        let push_all = |work: &mut [f64]| {
            let mut stream = Stream::new(&estimator, work).unwrap_or_else(|e| panic!("{e}"));
            for t in 0..samples {
                stream
                    .push(
                        black_box(&case.inputs[t * nu..(t + 1) * nu]),
                        black_box(&case.outputs[t * ny..(t + 1) * ny]),
                    )
                    .unwrap_or_else(|e| panic!("{e}"));
            }
        };
        let mut group = c.benchmark_group("runtime_push");
        group.throughput(Throughput::Elements(samples as u64));
        group.bench_function(case.name, |b| b.iter(|| push_all(&mut work)));
        group.finish();
        push_all(&mut work);
        let pushed = work.clone();
        let (mut theta, mut widths) = (vec![0.0; q], vec![0.0; q]);
        c.benchmark_group("runtime_finish")
            .bench_function(case.name, |b| {
                b.iter_batched_ref(
                    || pushed.clone(),
                    |work| {
                        let mut stream =
                            Stream::resume(&estimator, work).unwrap_or_else(|e| panic!("{e}"));
                        let a = stream
                            .finish(&mut theta, &mut widths)
                            .unwrap_or_else(|e| panic!("{e}"));
                        black_box((theta[0], a.feature_distance))
                    },
                    BatchSize::SmallInput,
                )
            });
        window(c, case, &estimator);
    }
}

/// A window of 3/4 of the record, full after its first samples: each
/// later push gains one sample and loses one.
fn window(c: &mut Criterion, case: &Case, estimator: &Estimator<'_>) {
    let (nu, ny) = (estimator.n_inputs(), estimator.n_outputs());
    let samples = case.outputs.len() / ny;
    let length = 3 * samples / 4;
    let q = estimator.n_parameters();
    let push = |work: &mut [f64], from: usize, to: usize| {
        let mut stream = Stream::resume(estimator, work).unwrap_or_else(|e| panic!("{e}"));
        for t in from..to {
            stream
                .push(
                    black_box(&case.inputs[t * nu..(t + 1) * nu]),
                    black_box(&case.outputs[t * ny..(t + 1) * ny]),
                )
                .unwrap_or_else(|e| panic!("{e}"));
        }
    };
    let mut filled = vec![0.0; estimator.window_workspace_len(length)];
    Stream::window(estimator, length, &mut filled).unwrap_or_else(|e| panic!("{e}"));
    push(&mut filled, 0, length);
    let mut group = c.benchmark_group("runtime_window_push");
    group.throughput(Throughput::Elements((samples - length) as u64));
    group.bench_function(case.name, |b| {
        b.iter_batched_ref(
            || filled.clone(),
            |work| push(work, length, samples),
            BatchSize::SmallInput,
        )
    });
    group.finish();
    push(&mut filled, length, samples);
    let (mut theta, mut widths) = (vec![0.0; q], vec![0.0; q]);
    c.benchmark_group("runtime_window_finish")
        .bench_function(case.name, |b| {
            b.iter_batched_ref(
                || filled.clone(),
                |work| {
                    let mut stream =
                        Stream::resume(estimator, work).unwrap_or_else(|e| panic!("{e}"));
                    let a = stream
                        .finish(&mut theta, &mut widths)
                        .unwrap_or_else(|e| panic!("{e}"));
                    black_box((theta[0], a.feature_distance))
                },
                BatchSize::SmallInput,
            )
        });
}

/// A finish that draws 1000 times from the posterior of a preset's
/// estimator trained with `--posterior 3` (the default network), and the
/// host's draws of the same record.
fn draws(c: &mut Criterion) {
    let count = 1000;
    for (name, model, preset, truth) in [
        (
            "benchmark_paper_posterior3",
            &Benchmark::new() as &dyn Simulator,
            twostage::paper_benchmark(),
            &[0.4][..],
        ),
        (
            "car_paper_posterior3",
            &PacejkaCar::new(),
            twostage::paper_pacejka(),
            &[-25.0, -1.0],
        ),
    ] {
        let host = TwoStage::builder(model)
            .preset(preset)
            .simulations(1000)
            .validation(0)
            .calibration(300)
            .posterior(MixtureDensity::with_components(3).unwrap_or_else(|e| panic!("{e}")))
            .train()
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let case = case_of(name, model, &host, truth);
        let estimator = Estimator::from_bytes(&case.blob).unwrap_or_else(|e| panic!("{e}"));
        let (nu, ny, q) = (
            estimator.n_inputs(),
            estimator.n_outputs(),
            estimator.n_parameters(),
        );
        let mut work = vec![0.0; estimator.workspace_len()];
        let mut stream = Stream::new(&estimator, &mut work).unwrap_or_else(|e| panic!("{e}"));
        for t in 0..case.outputs.len() / ny {
            stream
                .push(
                    &case.inputs[t * nu..(t + 1) * nu],
                    &case.outputs[t * ny..(t + 1) * ny],
                )
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let pushed = work.clone();
        let (mut theta, mut out) = (vec![0.0; q], vec![0.0; count * q]);
        let mut group = c.benchmark_group("runtime_draws");
        group.throughput(Throughput::Elements(count as u64));
        group.bench_function(name, |b| {
            b.iter_batched_ref(
                || pushed.clone(),
                |work| {
                    let mut stream =
                        Stream::resume(&estimator, work).unwrap_or_else(|e| panic!("{e}"));
                    stream
                        .finish_with_draws(&mut theta, &mut [], &mut out, 1, 0)
                        .unwrap_or_else(|e| panic!("{e}"));
                    black_box(out[0])
                },
                BatchSize::SmallInput,
            )
        });
        group.finish();
        let data = record(model, truth);
        let mut host_work = twostage::EstimateWorkspace::new();
        let mut group = c.benchmark_group("host_draws");
        group.throughput(Throughput::Elements(count as u64));
        group.bench_function(name, |b| {
            b.iter(|| {
                host.sample_into(
                    data.inputs(),
                    data.outputs(),
                    &mut host_work,
                    &mut stream_rng(1, 0, StreamPurpose::Posterior),
                    &mut out,
                )
                .unwrap_or_else(|e| panic!("{e}"));
                black_box(out[0])
            })
        });
        group.finish();
    }
}

criterion_group! {
    name = benches;
    config = config();
    targets = runtime, draws
}
criterion_main!(benches);
