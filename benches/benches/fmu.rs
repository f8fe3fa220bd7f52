//! The cost of simulating through an FMU against the same model in Rust,
//! with the test FMUs of crates/fmi/tests (built from C with gcc -O2):
//!
//! - `fmu_benchmark_record`: one record of eq. (5), N = 1000, built in and
//!   as FMI 2.0 and 3.0 co-simulation FMUs (the noises as noise inputs):
//!   the difference over N is the FMI overhead per communication step
//!   (set four inputs, get one output, one doStep).
//! - `fmu_pendulum_record`: one record of the pendulum, N = 200 samples of
//!   4 RK4 steps, in Rust and as FMI 2.0 and 3.0 model-exchange FMUs: the
//!   overhead per RK4 step (four derivative calls, each with setTime and
//!   setContinuousStates, and completedIntegratorStep).
//! - `fmu_chart`: 400 benchmark records through the FMI 2.0 FMU on 1 and 2
//!   threads (one instance per thread), and through its once-per-process
//!   variant in 2 worker processes (this bench binary, started as an FMU
//!   worker).

#[path = "../../crates/fmi/tests/common/mod.rs"]
mod fmus;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group};
use fmus::{PENDULUM_DIVISOR, PENDULUM_STEP};
use rayon::prelude::*;
use twostage::fmi::{FmiVersion, FmuSimulator};
use twostage::models::{
    Benchmark, Conditions, InputSignal, IoData, ModelSpec, Prior, Simulator, experiment_rng,
};
use twostage_benches::{config, slow_config};

const N: usize = 1000;

fn benchmark_fmu(path: &std::path::Path) -> FmuSimulator {
    let spec = ModelSpec::new(
        "benchmark-fmu",
        &["theta"],
        Prior::uniform_box(&[-0.9], &[0.9]).unwrap_or_else(|e| panic!("{e}")),
        1.0,
        N,
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .with_signals(&["u"], &["y"]);
    FmuSimulator::builder(path, spec)
        .input(InputSignal::white_gaussian(1.0).unwrap_or_else(|e| panic!("{e}")))
        .noise_input("v2", 0.1f64.sqrt())
        .noise_input("v11", 1.0)
        .noise_input("v12", 1.0)
        .build()
        .unwrap_or_else(|e| panic!("{e}"))
}

fn time_records(c: &mut Criterion, group: &str, sims: &[(&str, &dyn Simulator)], theta: &[f64]) {
    let mut group = c.benchmark_group(group);
    group.throughput(Throughput::Elements(1));
    for (name, sim) in sims {
        let mut record = IoData::default();
        let mut index = 0u64;
        group.bench_function(*name, |b| {
            b.iter(|| {
                index += 1;
                sim.simulate(theta, &mut experiment_rng(3, index), &mut record)
                    .unwrap_or_else(|e| panic!("{e}"));
            })
        });
    }
    group.finish();
}

fn benchmark_record(c: &mut Criterion) {
    let v2 = fmus::build(fmus::Model::Benchmark, FmiVersion::V2);
    let v3 = fmus::build(fmus::Model::Benchmark, FmiVersion::V3);
    let builtin = Benchmark::new();
    let (fmi2, fmi3) = (benchmark_fmu(&v2.path), benchmark_fmu(&v3.path));
    time_records(
        c,
        "fmu_benchmark_record",
        &[
            ("builtin", &builtin),
            ("fmi2_cs", &fmi2),
            ("fmi3_cs", &fmi3),
        ],
        &[0.5],
    );
}

/// The pendulum of crates/fmi/tests/fmus/pendulum.c in Rust (the tests'
/// reference), as a simulator.
struct Pendulum {
    spec: ModelSpec,
}

impl Simulator for Pendulum {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut twostage::models::ExperimentRng,
        _: Conditions<'_>,
        out: &mut IoData,
    ) -> twostage::models::Result<()> {
        let n = self.spec.n_samples();
        out.resize(n, 1, 1);
        InputSignal::white_gaussian(0.5)?.fill(fmus::PENDULUM_STEP, rng, out.input_mut(0))?;
        let y = fmus::pendulum_in_rust(theta[0], theta[1], out.input(0), None);
        out.output_mut(0).copy_from_slice(&y);
        Ok(())
    }
}

fn pendulum_record(c: &mut Criterion) {
    let spec = ModelSpec::new(
        "pendulum",
        &["k", "c"],
        Prior::uniform_box(&[0.5, 0.05], &[4.0, 1.0]).unwrap_or_else(|e| panic!("{e}")),
        PENDULUM_STEP,
        200,
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .with_signals(&["u"], &["y"]);
    let fmu = |version| {
        let built = fmus::build(fmus::Model::Pendulum, version);
        let sim = FmuSimulator::builder(&built.path, spec.clone())
            .input(InputSignal::white_gaussian(0.5).unwrap_or_else(|e| panic!("{e}")))
            .step_divisor(PENDULUM_DIVISOR)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        (built, sim)
    };
    let ((_keep2, fmi2), (_keep3, fmi3)) = (fmu(FmiVersion::V2), fmu(FmiVersion::V3));
    let rust = Pendulum { spec: spec.clone() };
    time_records(
        c,
        "fmu_pendulum_record",
        &[("rust_rk4", &rust), ("fmi2_me", &fmi2), ("fmi3_me", &fmi3)],
        &[1.5, 0.3],
    );
}

fn chart(c: &mut Criterion) {
    const RECORDS: usize = 400;
    let built = fmus::build(fmus::Model::Benchmark, FmiVersion::V2);
    let once = fmus::build(fmus::Model::BenchmarkOnce, FmiVersion::V2);
    let sims = [
        ("fmi2_cs_threads", benchmark_fmu(&built.path)),
        ("fmi2_cs_workers", benchmark_fmu(&once.path)),
    ];
    let mut group = c.benchmark_group("fmu_chart");
    group.throughput(Throughput::Elements(RECORDS as u64));
    for ((name, sim), threads) in [(&sims[0], 1usize), (&sims[0], 2), (&sims[1], 2)] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        group.bench_function(BenchmarkId::new(*name, threads), |b| {
            b.iter(|| {
                pool.install(|| {
                    (0..RECORDS as u64).into_par_iter().for_each_init(
                        IoData::default,
                        |record, i| {
                            sim.simulate(&[0.5], &mut experiment_rng(4, i), record)
                                .unwrap_or_else(|e| panic!("{e}"));
                        },
                    )
                })
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = records;
    config = config();
    targets = benchmark_record, pendulum_record
}
criterion_group! {
    name = charts;
    config = slow_config();
    targets = chart
}
fn main() {
    // The bench binary is also the worker of the once-per-process FMU.
    twostage::fmi::serve_workers_from_this_program();
    records();
    charts();
    Criterion::default().configure_from_args().final_summary();
}
