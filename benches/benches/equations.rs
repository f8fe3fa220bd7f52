//! The cost of a record of a model written as equations (compiled by
//! Cranelift)
//! against the same model in Rust: the paper's benchmark, eq. (5), 1000
//! samples, built in (`equations/builtin`) and as
//! `benches/models/benchmark_equations.toml` (`equations/equations`),
//! noise and input drawn alike. Issue 38's goal: within 3 times.

use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use twostage::ModelFile;
use twostage::models::{Benchmark, IoData, Simulator, experiment_rng};
use twostage_benches::config;

fn equations(c: &mut Criterion) {
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models/benchmark_equations.toml");
    let written = ModelFile::load(&file)
        .and_then(|f| f.simulator())
        .unwrap_or_else(|e| panic!("{e}"));
    let builtin = Benchmark::new();
    let mut group = c.benchmark_group("equations");
    group.throughput(Throughput::Elements(1));
    let models: [(&str, &dyn Simulator); 2] = [("builtin", &builtin), ("equations", &*written)];
    for (name, model) in models {
        let mut record = IoData::default();
        let mut index = 0u64;
        group.bench_function(name, |b| {
            b.iter(|| {
                index += 1;
                model
                    .simulate(&[0.5], &mut experiment_rng(1, index), &mut record)
                    .unwrap_or_else(|e| panic!("{e}"));
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = config();
    targets = equations
}
criterion_main!(benches);
