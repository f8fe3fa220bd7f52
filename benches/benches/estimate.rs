//! The cost of one estimate on one recorded experiment, per method.
//!
//! Groups: `estimate_cost_benchmark` (ts, ts_recommended, ekf, ukf,
//! pf1000, pem1, pem5, pem10, bayes, ii5) and `estimate_cost_pacejka` (ts,
//! ts_recommended, ts_learned, ts_linearized, ts_linearized1, pf500,
//! pem5), every method on the same record of its group. `ts` is the paper
//! preset, `ts_recommended` the recommended one, `ts_learned` ARX, the
//! summary and a learned summary (`arx:2,2+summary+learned`,
//! `ensemble:10`), `ts_linearized` the car linearized at the prior's
//! centre (`linearized`, two Runge-Kutta steps a sample; `ts_linearized1`
//! one), `ensemble:10`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use twostage::models::{Benchmark, BuiltinModel, IoData, PacejkaCar};
use twostage::{ClassicMethod, EstimateWorkspace, Estimator, ModelProfile, TwoStage};
use twostage_baselines::{MethodSettings, RecordEstimator, classic_estimator};
use twostage_benches::{config, record, slow_config};

/// The model's preset `name`, trained (seed 1, no calibration or
/// validation).
fn trained(
    model: &dyn twostage::models::Simulator,
    builtin: BuiltinModel,
    name: &str,
) -> Estimator {
    let preset = ModelProfile::of(builtin)
        .preset(name)
        .unwrap_or_else(|e| panic!("{e}"));
    TwoStage::builder(model)
        .preset(preset)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_or_else(|e| panic!("training the {builtin} {name} preset: {e}"))
}

/// `model`'s estimator of stage 1 `compressor` and `ensemble:10` on 1000
/// records.
fn trained_with(model: &dyn twostage::models::Simulator, compressor: &str) -> Estimator {
    TwoStage::builder(model)
        .compressor(
            compressor
                .parse::<twostage::CompressorConfig>()
                .unwrap_or_else(|e| panic!("{e}")),
        )
        .regressor(
            "ensemble:10"
                .parse::<twostage::RegressorConfig>()
                .unwrap_or_else(|e| panic!("{e}")),
        )
        .simulations(1000)
        .validation(0)
        .calibration(0)
        .seed(1)
        .train()
        .unwrap_or_else(|e| panic!("training {compressor}: {e}"))
}

fn bench_ts(
    c: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    id: &str,
    estimator: &Estimator,
    data: &IoData,
) {
    let mut work = EstimateWorkspace::new();
    let mut theta = vec![0.0; estimator.param_names().len()];
    c.bench_function(id, |b| {
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

/// A classic method as the per-model table builds it (seed 0).
fn classic(model: BuiltinModel, method: ClassicMethod, starts: usize) -> Box<dyn RecordEstimator> {
    let settings = MethodSettings {
        starts,
        ..MethodSettings::default()
    };
    classic_estimator(model, method, &settings)
        .unwrap_or_else(|e| panic!("{method} for {model}: {e}"))
}

fn benchmark_costs(c: &mut Criterion) {
    use ClassicMethod as M;
    let model = BuiltinModel::Benchmark;
    let profile = ModelProfile::of(model);
    let bench = Benchmark::new();
    let estimator = trained(&bench, model, "paper");
    let recommended = trained(&bench, model, "recommended");
    let data = record(&bench, &[0.5]);
    let mut group = c.benchmark_group("estimate_cost_benchmark");
    bench_ts(&mut group, "ts", &estimator, &data);
    bench_ts(&mut group, "ts_recommended", &recommended, &data);
    bench_method(&mut group, "ekf", classic(model, M::Ekf, 1).as_ref(), &data);
    bench_method(&mut group, "ukf", classic(model, M::Ukf, 1).as_ref(), &data);
    for starts in [1, 5, 10] {
        let pem = classic(model, M::PredictionError, starts);
        bench_method(&mut group, &format!("pem{starts}"), pem.as_ref(), &data);
    }
    group.finish();
    let mut group = c.benchmark_group("estimate_cost_benchmark");
    group.sample_size(10);
    let pf = classic(model, M::ParticleFilter, 1);
    let name = format!("pf{}", profile.default_particles());
    bench_method(&mut group, &name, pf.as_ref(), &data);
    bench_method(
        &mut group,
        "bayes",
        classic(model, M::Bayes, 1).as_ref(),
        &data,
    );
    // Indirect inference through the preset's ARX(5, 5): S = 10, W from 200
    // simulations (built once, outside the timing, as for a deployed method).
    let ii5 = classic(model, M::IndirectInference, 5);
    bench_method(&mut group, "ii5", ii5.as_ref(), &data);
    group.finish();
}

fn pacejka_costs(c: &mut Criterion) {
    use ClassicMethod as M;
    let model = BuiltinModel::Pacejka;
    let profile = ModelProfile::of(model);
    let car = PacejkaCar::new();
    let estimator = trained(&car, model, "paper");
    let recommended = trained(&car, model, "recommended");
    let data = record(&car, &[-35.0, -1.1]);
    let mut group = c.benchmark_group("estimate_cost_pacejka");
    bench_ts(&mut group, "ts", &estimator, &data);
    bench_ts(&mut group, "ts_recommended", &recommended, &data);
    // A learned stage 1 (the ARX fit, the summary and the network's pass
    // over the record), and the car linearized at the prior's centre (its
    // simulation with the output's derivatives along the record, then the
    // least-squares step), each before the same kind of stage 2.
    for (name, spec) in [
        ("ts_learned", "arx:2,2+summary+learned"),
        ("ts_linearized", "linearized"),
        ("ts_linearized1", "linearized:1"),
    ] {
        bench_ts(&mut group, name, &trained_with(&car, spec), &data);
    }
    group.finish();
    let mut group = c.benchmark_group("estimate_cost_pacejka");
    group.sample_size(10);
    let pf = classic(model, M::ParticleFilter, 1);
    let name = format!("pf{}", profile.default_particles());
    bench_method(&mut group, &name, pf.as_ref(), &data);
    let pem5 = classic(model, M::PredictionError, 5);
    bench_method(&mut group, "pem5", pem5.as_ref(), &data);
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
