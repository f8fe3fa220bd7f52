//! The particle filter, the prediction-error method and the Bayes reference
//! on the benchmark.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage_baselines::{
    BayesBenchmark, BenchmarkParticles, BenchmarkPredictor, ParticleFilter, PredictionError,
    RecordEstimator, benchmark_kalman,
};
use twostage_models::{Benchmark, IoData, Simulator, experiment_rng};

fn record(theta: f64, seed: u64) -> IoData {
    let model = Benchmark::new();
    let mut record = model.spec().new_record();
    model
        .simulate(&[theta], &mut experiment_rng(seed, 0), &mut record)
        .unwrap();
    record
}

#[test]
fn the_particle_filter_finds_an_easy_theta_the_same_way_on_any_thread_count() {
    let data = record(0.3, 10);
    // 2000 particles: with a few hundred the cloud sometimes collapses on a
    // wrong mode of this multimodal likelihood (the method's known weakness).
    let pf = ParticleFilter::new(BenchmarkParticles::new().unwrap(), 2000).seed(3);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| pf.estimate(&data).unwrap())
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.theta[0].to_bits(), two.theta[0].to_bits());
    assert!(
        (one.theta[0] - 0.3).abs() < 0.03,
        "PF estimate {:?}",
        one.theta
    );
    assert!(one.spread.unwrap()[0] < 0.05);
    assert_eq!(pf.name(), "pf2000");
}

#[test]
fn prediction_error_with_restarts_finds_the_global_minimum() {
    let data = record(0.5, 11);
    let pem = PredictionError::new(BenchmarkPredictor::new(), 10).seed(1);
    let descents = pem.descents(&data).unwrap();
    assert_eq!(descents.len(), 10);
    assert!(descents.windows(2).all(|w| w[0].loss <= w[1].loss));
    let best = &descents[0];
    assert!((best.theta[0] - 0.5).abs() < 0.03, "{best:?}");
    // The loss is the sum of squared Kalman innovations at the estimate.
    let sse = benchmark_kalman(best.theta[0], &data)
        .unwrap()
        .sum_squared_innovations;
    assert!((sse - best.loss).abs() < 1e-9 * sse);
    // Its neighbourhood holds no lower loss: a true local minimum.
    for d in [-1e-3, 1e-3] {
        let nearby = benchmark_kalman(best.theta[0] + d, &data)
            .unwrap()
            .sum_squared_innovations;
        assert!(nearby >= best.loss);
    }
}

#[test]
fn the_posterior_mean_no_longer_moves_when_the_grid_is_refined() {
    let data = record(-0.62, 12);
    let default = BayesBenchmark::default().posterior(&data).unwrap();
    let finer = BayesBenchmark::default()
        .initial_points(7201)
        .posterior(&data)
        .unwrap();
    assert!(
        (default.mean - finer.mean).abs() < 1e-6,
        "{default:?}\n{finer:?}"
    );
    assert!((default.sd - finer.sd).abs() < 1e-6);
    assert!((default.mean + 0.62).abs() < 0.1, "{default:?}");
    assert!(default.sd > 1e-4 && default.sd < 0.1);
}

#[test]
fn the_posterior_matches_brute_force_quadrature() {
    // An independent computation: Simpson's rule on a uniform grid ten
    // times finer than the adaptive one's start, no refinement.
    let data = record(0.27, 13);
    let adaptive = BayesBenchmark::default().posterior(&data).unwrap();
    let n = 18_001;
    let h = 1.8 / (n - 1) as f64;
    let thetas: Vec<f64> = (0..n).map(|i| -0.9 + h * i as f64).collect();
    let ll: Vec<f64> = thetas
        .iter()
        .map(|&t| benchmark_kalman(t, &data).unwrap().log_likelihood)
        .collect();
    let peak = ll.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
    let (mut mass, mut first) = (0.0, 0.0);
    for i in 0..n {
        let w = if i == 0 || i == n - 1 {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let p = (ll[i] - peak).exp();
        mass += w * p;
        first += w * p * thetas[i];
    }
    let mean = first / mass;
    assert!(
        (adaptive.mean - mean).abs() < 1e-6,
        "adaptive {} vs Simpson {mean}",
        adaptive.mean
    );
}

#[test]
fn refining_with_the_exact_likelihood_stays_in_its_box_and_more_starts_never_end_higher() {
    use twostage::{RefineStarts, Refinement};
    let pe = Refinement::new(BenchmarkPredictor::new());
    for (i, truth) in [-0.62, -0.2, 0.35, 0.71].into_iter().enumerate() {
        let data = record(truth, 40 + i as u64);
        let start = [truth + 0.02];
        let radius = [0.05];
        let one = pe
            .refine(&data, &start, &radius, RefineStarts::Centre)
            .unwrap();
        let three = pe
            .refine(&data, &start, &radius, RefineStarts::CentreAndAxes)
            .unwrap();
        for d in [&one, &three] {
            assert!((d.theta[0] - start[0]).abs() <= radius[0] + 1e-12, "{d:?}");
        }
        assert!(three.loss <= one.loss, "{three:?} vs {one:?}");
        // From next to the truth, the box holds the likelihood's peak.
        assert!((three.theta[0] - truth).abs() < 0.04, "{three:?}");
    }
    assert!(
        pe.refine(&record(0.1, 1), &[0.1], &[-1.0], RefineStarts::Centre)
            .is_err()
    );
}

#[test]
fn the_benchmark_reference_draws_have_the_posterior_s_moments() {
    use rand::SeedableRng;
    let data = record(0.41, 14);
    let bayes = BayesBenchmark::default();
    let posterior = bayes.posterior(&data).unwrap();
    let n = 40_000;
    let draws = bayes
        .draws(&data, n, &mut rand_chacha::ChaCha8Rng::seed_from_u64(1))
        .unwrap();
    let mean = draws.iter().sum::<f64>() / n as f64;
    let sd = (draws.iter().map(|d| (d - mean) * (d - mean)).sum::<f64>() / n as f64).sqrt();
    // Monte Carlo: the mean within 4 of its standard errors, the sd
    // within 3% (its standard error is 0.35% for a near-normal sample).
    let error = posterior.sd / (n as f64).sqrt();
    assert!(
        (mean - posterior.mean).abs() < 4.0 * error,
        "{mean} {posterior:?}"
    );
    assert!((sd / posterior.sd - 1.0).abs() < 0.03, "{sd} {posterior:?}");
    assert!(draws.iter().all(|d| (-0.9..=0.9).contains(d)));
}
