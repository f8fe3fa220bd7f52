//! The benchmark system of eq. (5) against closed forms.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage_models::{Benchmark, SimError, Simulator, experiment_rng};

/// Stationary variance of y for eq. (5), derived by hand from the discrete
/// Lyapunov equation P = A P A' + Q, with A = [[1/2, 0], [a, -theta]],
/// B = [1, b]' and Q = B B' + I (u, v11, v12 all of unit variance):
/// p11 = 8/3, p12 = (a p11 / 2 + b) / (1 + theta / 2),
/// p22 = (a^2 p11 - 2 a theta p12 + 1 + b^2) / (1 - theta^2), var y = p22 + 0.1.
fn lyapunov_output_variance(theta: f64) -> f64 {
    let (a, b) = Benchmark::coefficients(theta);
    let p11 = 8.0 / 3.0;
    let p12 = (0.5 * a * p11 + b) / (1.0 + 0.5 * theta);
    let p22 = (a * a * p11 - 2.0 * a * theta * p12 + 1.0 + b * b) / (1.0 - theta * theta);
    p22 + 0.1
}

/// The same quantity by iterating P <- A P A' + Q to its fixed point: a
/// second computation that checks the algebra above.
fn iterated_output_variance(theta: f64) -> f64 {
    let (a, b) = Benchmark::coefficients(theta);
    let (mut p11, mut p12, mut p22) = (0.0, 0.0, 0.0);
    for _ in 0..5000 {
        let n11 = 0.25 * p11 + 2.0;
        let n12 = 0.5 * (a * p11 - theta * p12) + b;
        let n22 = a * a * p11 - 2.0 * a * theta * p12 + theta * theta * p22 + 1.0 + b * b;
        (p11, p12, p22) = (n11, n12, n22);
    }
    p22 + 0.1
}

#[test]
fn stationary_output_variance_matches_the_lyapunov_equation() {
    let n = 400_000;
    let model = Benchmark::builder().n_samples(n).build().unwrap();
    let mut record = model.spec().new_record();
    for (i, theta) in [-0.7, 0.2, 0.55, 0.85].into_iter().enumerate() {
        let closed = lyapunov_output_variance(theta);
        assert!((closed / iterated_output_variance(theta) - 1.0).abs() < 1e-12);
        model
            .simulate(&[theta], &mut experiment_rng(77, i as u64), &mut record)
            .unwrap();
        let y = &record.output(0)[1000..];
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        let var = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / y.len() as f64;
        // Relative standard error below 0.6% for these theta (correlation
        // time at most about 6 samples): 3% is five standard errors.
        assert!(
            (var / closed - 1.0).abs() < 0.03,
            "theta {theta}: sample variance {var}, Lyapunov {closed}"
        );
    }
}

#[test]
fn noise_free_records_follow_the_recursion_of_eq_5() {
    let model = twostage_models::NoiseFree::new(Box::new(
        Benchmark::builder().n_samples(50).build().unwrap(),
    ))
    .unwrap();
    let mut record = model.spec().new_record();
    let theta = -0.45;
    model
        .simulate(&[theta], &mut experiment_rng(1, 1), &mut record)
        .unwrap();
    let (u, y) = (record.input(0), record.output(0));
    let (a, b) = Benchmark::coefficients(theta);
    // y(k+2) = x2(k+2) = a x1(k+1) - theta x2(k+1) + b u(k+1), with
    // x1(k+1) = x1(k) / 2 + u(k) rebuilt from the inputs.
    let mut x1 = 0.0;
    for k in 0..48 {
        x1 = 0.5 * x1 + u[k];
        let predicted = a * x1 - theta * y[k + 1] + b * u[k + 1];
        assert!((predicted - y[k + 2]).abs() < 1e-12 * (1.0 + y[k + 2].abs()));
    }
    assert_eq!(y[0].to_bits(), 0.0f64.to_bits(), "x2(0) = 0 and no noise");
}

#[test]
fn an_unstable_theta_is_reported_with_its_time() {
    let model = Benchmark::new();
    let mut record = model.spec().new_record();
    let err = model
        .simulate(&[3.0], &mut experiment_rng(0, 0), &mut record)
        .unwrap_err();
    match err {
        SimError::Diverged { theta, time } => {
            assert_eq!(theta, vec![3.0]);
            assert!(time > 100.0 && time < 1000.0, "time {time}");
        }
        other => panic!("expected a divergence, got {other}"),
    }
    assert!(
        model
            .simulate(&[0.1, 0.2], &mut experiment_rng(0, 0), &mut record)
            .is_err()
    );
    assert!(
        model
            .simulate(&[f64::NAN], &mut experiment_rng(0, 0), &mut record)
            .is_err()
    );
}
