//! Experiment i of seed s is the same bits whatever the thread count.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rayon::prelude::*;
use twostage_models::{
    Benchmark, BuiltinModel, IoData, PacejkaCar, Prior, Sampling, Simulator, run_experiment,
};

fn chart_bits<S: Simulator>(model: &S, m: usize, seed: u64, threads: usize) -> Vec<u64> {
    let design = model.prior().design(m, seed).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let per_experiment: Vec<Vec<u64>> = pool.install(|| {
        (0..m)
            .into_par_iter()
            .map_init(
                || (vec![0.0; model.prior().dim()], IoData::default()),
                |(theta, record), i| {
                    run_experiment(model, &design, i, theta, record).unwrap();
                    theta
                        .iter()
                        .chain(record.input(0))
                        .chain(record.output(0))
                        .map(|v| v.to_bits())
                        .collect()
                },
            )
            .collect()
    });
    per_experiment.concat()
}

#[test]
fn benchmark_charts_are_identical_with_one_and_two_threads() {
    let model = Benchmark::new();
    let one = chart_bits(&model, 64, 2024, 1);
    assert_eq!(one, chart_bits(&model, 64, 2024, 2));
    assert_ne!(one, chart_bits(&model, 64, 2025, 2));
}

#[test]
fn pacejka_charts_are_identical_with_one_and_two_threads() {
    let model = PacejkaCar::new();
    assert_eq!(chart_bits(&model, 16, 7, 1), chart_bits(&model, 16, 7, 2));
}

#[test]
fn every_design_gives_thread_independent_charts() {
    for sampling in [Sampling::LatinHypercube, Sampling::Sobol] {
        let model = Benchmark::builder().n_samples(100).build().unwrap();
        let design = Prior::uniform_box(&[-0.9], &[0.9])
            .unwrap()
            .with_sampling(sampling)
            .design(32, 3)
            .unwrap();
        let run = |threads: usize| -> Vec<u64> {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                (0..32)
                    .into_par_iter()
                    .flat_map_iter(|i| {
                        let (mut theta, mut record) = ([0.0], IoData::default());
                        run_experiment(&model, &design, i, &mut theta, &mut record).unwrap();
                        let mut bits = vec![theta[0].to_bits()];
                        bits.extend(record.output(0).iter().map(|v| v.to_bits()));
                        bits
                    })
                    .collect()
            })
        };
        assert_eq!(run(1), run(2), "{sampling:?}");
    }
}

#[test]
fn builtin_models_describe_themselves() {
    for model in BuiltinModel::ALL {
        let sim = model.build().unwrap();
        let spec = sim.spec();
        assert_eq!(spec.name(), model.name());
        assert_eq!(spec.param_names().len(), spec.prior().dim());
        assert!(!spec.input_note().is_empty() && !spec.noise_note().is_empty());
    }
}
