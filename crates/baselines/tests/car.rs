//! The competitors on the Pacejka car.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::ResidualModel;
use twostage_baselines::{
    BayesCar, CarParticles, CarPredictor, ParticleFilter, PredictionError, RecordEstimator,
};
use twostage_models::{Conditions, IoData, PacejkaCar, Simulator, experiment_rng};

fn car_record(theta: [f64; 2], noiseless: bool, n: usize, seed: u64) -> IoData {
    let car = PacejkaCar::builder().n_samples(n).build().unwrap();
    let mut record = car.spec().new_record();
    let conditions = Conditions {
        noiseless,
        input: None,
    };
    car.simulate_under(
        &theta,
        &mut experiment_rng(seed, 0),
        conditions,
        &mut record,
    )
    .unwrap();
    record
}

#[test]
fn the_predictor_reproduces_the_simulator_exactly() {
    let record = car_record([-31.0, -1.05], true, 500, 1);
    let mut residuals = vec![0.0; 500];
    CarPredictor::new()
        .residuals(&[-31.0, -1.05], &record, &mut residuals)
        .unwrap();
    assert!(
        residuals.iter().all(|r| r.abs() < 1e-12),
        "largest {:?}",
        residuals.iter().fold(0.0f64, |m, r| m.max(r.abs()))
    );
}

#[test]
fn prediction_error_recovers_both_parameters_from_clean_data() {
    let truth = [-36.5, -1.13];
    let record = car_record(truth, true, 500, 2);
    let estimate = PredictionError::new(CarPredictor::new(), 3)
        .seed(4)
        .estimate(&record)
        .unwrap();
    assert!(
        (estimate.theta[0] - truth[0]).abs() < 1e-3,
        "{:?}",
        estimate.theta
    );
    assert!(
        (estimate.theta[1] - truth[1]).abs() < 1e-4,
        "{:?}",
        estimate.theta
    );
}

#[test]
fn the_particle_filter_locates_pk1_on_a_noisy_record() {
    // 250 samples reach 5 s, well into the chicane.
    let truth = [-35.0, -1.1];
    let record = car_record(truth, false, 250, 3);
    let pf = ParticleFilter::new(CarParticles::new(), 200).seed(1);
    let e = pf.estimate(&record).unwrap();
    assert!((e.theta[0] - truth[0]).abs() < 3.0, "{:?}", e.theta);
    assert!((-1.22..=-0.98).contains(&e.theta[1]));
}

#[test]
fn the_car_posterior_is_resolved_by_its_grid() {
    let bayes = BayesCar::new(65, 33, 500).unwrap();
    let truth = [-33.0, -1.07];
    let record = car_record(truth, false, 500, 5);
    let p = bayes.posterior(&record).unwrap();
    // Halving the grid's resolution moves the mean by a small fraction of
    // the posterior's spread: the integration error of the full grid is
    // smaller still.
    for d in 0..2 {
        assert!(p.grid_change[d] < 0.05 * p.sd[d], "{p:?}");
    }
    assert!((p.mean[0] - truth[0]).abs() < 4.0 * p.sd[0] + 0.1, "{p:?}");
    assert!(p.sd[0] > 0.1 && p.sd[0] < 2.0, "{p:?}");
    let short = car_record(truth, false, 100, 5);
    assert!(bayes.posterior(&short).is_err());
}

#[test]
fn local_refinement_no_longer_moves_the_car_posterior_mean() {
    // A short record (5 s) keeps the simulations cheap; the posterior is wider.
    let bayes = BayesCar::new(33, 17, 250).unwrap();
    let record = car_record([-38.0, -1.02], false, 250, 6);
    let grid = bayes.posterior(&record).unwrap();
    let (refined, levels) = bayes.refine(&record, &grid, 1e-3, 4).unwrap();
    assert!((2..=4).contains(&levels), "{levels} levels");
    for d in 0..2 {
        // Converged: the last doubling moved the mean by under 1e-3 sd...
        assert!(refined.grid_change[d] < 1e-3 * refined.sd[d], "{refined:?}");
        // ...and the refined mean agrees with the shared grid's.
        assert!(
            (refined.mean[d] - grid.mean[d]).abs() < 0.05 * grid.sd[d],
            "{grid:?}\n{refined:?}"
        );
    }
}

#[test]
fn a_grid_on_a_given_steering_is_the_chicane_s_when_given_the_chicane() {
    // The chicane's own samples as a given steering: the car then follows
    // them linearly between samples instead of the chicane's formula, so
    // the two posteriors of one record differ by a small share of their
    // spread, and each sits where the other does.
    let chicane = BayesCar::new(33, 17, 250).unwrap();
    let record = car_record([-34.0, -1.08], false, 250, 7);
    let given = BayesCar::on_steering(33, 17, record.input(0).to_vec()).unwrap();
    let (a, b) = (
        chicane.posterior(&record).unwrap(),
        given.posterior(&record).unwrap(),
    );
    for d in 0..2 {
        assert!(
            (a.mean[d] - b.mean[d]).abs() < 0.1 * a.sd[d],
            "{a:?}\n{b:?}"
        );
    }
    // A record of another steering is not the grid's.
    let mut other = record.clone();
    other.input_mut(0)[100] += 0.01;
    let e = given.posterior(&other).unwrap_err().to_string();
    assert!(e.contains("steering"), "{e}");
}

#[test]
fn the_car_reference_draws_have_the_refined_posterior_s_moments() {
    use rand::SeedableRng;
    let bayes = BayesCar::new(33, 17, 250).unwrap();
    let record = car_record([-35.0, -1.06], false, 250, 8);
    let grid = bayes.posterior(&record).unwrap();
    let (refined, _) = bayes.refine(&record, &grid, 1e-2, 3).unwrap();
    let n = 40_000;
    // Steps of 0.375 sd: the interpolation widens the sd by about 1.2%.
    let draws = bayes
        .draws(
            &record,
            n,
            33,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(2),
        )
        .unwrap();
    for d in 0..2 {
        let mean = draws.iter().map(|v| v[d]).sum::<f64>() / n as f64;
        let sd = (draws.iter().map(|v| (v[d] - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        let error = refined.sd[d] / (n as f64).sqrt();
        assert!(
            (mean - refined.mean[d]).abs() < 4.0 * error + 0.01 * refined.sd[d],
            "{d}: {mean} {refined:?}"
        );
        assert!(
            (sd / refined.sd[d] - 1.0).abs() < 0.03,
            "{d}: {sd} {refined:?}"
        );
    }
    assert!(
        bayes
            .draws(
                &record,
                10,
                2,
                &mut rand_chacha::ChaCha8Rng::seed_from_u64(2)
            )
            .is_err()
    );
    let car = PacejkaCar::builder().n_samples(250).build().unwrap();
    let (lo, hi) = (car.prior().lower(), car.prior().upper());
    assert!(
        draws
            .iter()
            .all(|v| (0..2).all(|d| (lo[d]..=hi[d]).contains(&v[d])))
    );
}
