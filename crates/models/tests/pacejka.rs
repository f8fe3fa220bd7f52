//! The Pacejka car against the spec's golden values and against physics.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use twostage_models::{
    InputSignal, NoiseFree, PacejkaCar, Simulator, Tire, Vehicle, experiment_rng,
};

/// `tests/data/pacejka-golden.csv`: the reference values of
/// `spec/pacejka-car.md`, copied into the repository so that a fresh clone
/// tests on its own; `TWOSTAGE_PACEJKA_GOLDEN` names another file (a newer
/// spec's, say).
fn golden_path() -> PathBuf {
    if let Some(path) = std::env::var_os("TWOSTAGE_PACEJKA_GOLDEN") {
        return PathBuf::from(path);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/pacejka-golden.csv")
}

fn simulate(car: &dyn Simulator, theta: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut record = car.spec().new_record();
    car.simulate(theta, &mut experiment_rng(0, 0), &mut record)
        .expect("simulation inside the prior box succeeds");
    (record.input(0).to_vec(), record.output(0).to_vec())
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= (1e-6 * want.abs()).max(1e-9)
}

#[test]
fn reproduces_every_golden_row() {
    let path = golden_path();
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "the golden file {} cannot be read ({e}): restore it from git, or \
             point TWOSTAGE_PACEJKA_GOLDEN at a pacejka-golden.csv",
            path.display()
        )
    });
    let car = NoiseFree::new(Box::new(PacejkaCar::new())).unwrap();
    let mut rows = 0;
    let mut cache: Option<([f64; 2], Vec<f64>, Vec<f64>)> = None;
    for (line_no, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse().expect("golden values are numbers"))
            .collect();
        assert_eq!(v.len(), 6, "line {}: pK1,pK2,k,t,u,y", line_no + 1);
        let theta = [v[0], v[1]];
        let k = v[2] as usize;
        if cache
            .as_ref()
            .is_none_or(|(t, _, _)| t.map(f64::to_bits) != theta.map(f64::to_bits))
        {
            let (u, y) = simulate(&car, &theta);
            cache = Some((theta, u, y));
        }
        let (_, u, y) = cache.as_ref().unwrap();
        assert!(
            (k as f64 * 0.02 - v[3]).abs() < 1e-9,
            "line {}: sample {k} is not at t = {}",
            line_no + 1,
            v[3]
        );
        assert!(
            close(u[k], v[4]),
            "line {}: u[{k}] = {} != {}",
            line_no + 1,
            u[k],
            v[4]
        );
        assert!(
            close(y[k], v[5]),
            "line {}: y[{k}] = {} != {}",
            line_no + 1,
            y[k],
            v[5]
        );
        rows += 1;
    }
    assert!(
        rows >= 26,
        "only {rows} golden rows read from {}",
        path.display()
    );
}

/// Cornering stiffness of one wheel at load q: dF/dalpha at alpha = 0, which
/// is K = B C D of the magic formula.
fn wheel_stiffness(tire: &Tire, q: f64, p_k1: f64, p_k2: f64) -> f64 {
    p_k1 * tire.fz0 * (2.0 * (q / (p_k2 * tire.fz0)).atan()).sin()
}

#[test]
fn small_constant_steer_gives_the_linear_single_track_gain() {
    // Steady state of the linear single-track model (e.g. Rajamani, Vehicle
    // Dynamics and Control, ch. 3): delta = L a_y / V^2 + K_us a_y with
    // K_us = m / L (lr / C_f - lf / C_r), C_f, C_r the axle stiffnesses.
    let delta = 1e-3;
    let n = 1500; // 30 s: every mode has settled
    let car = PacejkaCar::builder()
        .n_samples(n)
        .input(InputSignal::fixed(vec![delta; n]).unwrap())
        .build()
        .unwrap();
    let car = NoiseFree::new(Box::new(car)).unwrap();
    let v = Vehicle::PAPER;
    let tire = Tire::PAPER;
    let (n_f, n_r) = v.axle_loads();
    for theta in [[-35.0, -1.1], [-42.83, -0.98], [-27.32, -1.22]] {
        let (_, y) = simulate(&car, &theta);
        let c_f = 2.0 * wheel_stiffness(&tire, n_f / 2.0, theta[0], theta[1]);
        let c_r = 2.0 * wheel_stiffness(&tire, n_r / 2.0, theta[0], theta[1]);
        let wheelbase = v.lf + v.lr;
        let k_us = v.mass / wheelbase * (v.lr / c_f - v.lf / c_r);
        let gain = 1.0 / (wheelbase / (v.speed * v.speed) + k_us);
        let steady = y[n - 1];
        assert!(
            (steady / (gain * delta) - 1.0).abs() < 1e-3,
            "theta {theta:?}: a_y = {steady}, linear theory {}",
            gain * delta
        );
        assert!((y[n - 1] - y[n - 50]).abs() < 1e-9 * gain, "not settled");
    }
}

#[test]
fn the_chicane_is_stable_over_the_whole_prior_box() {
    // The spec: peaks of about 6.2 to 6.4 m/s^2 over the box, and the car
    // settles once the chicane ends at t = 9 s.
    let car = NoiseFree::new(Box::new(PacejkaCar::new())).unwrap();
    let corners = [
        [-42.83, -1.22],
        [-42.83, -0.98],
        [-27.32, -1.22],
        [-27.32, -0.98],
        [-35.0, -1.1],
    ];
    for theta in corners {
        let (_, y) = simulate(&car, &theta);
        let peak = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((6.1..6.5).contains(&peak), "theta {theta:?}: peak {peak}");
        assert!(
            y[499].abs() < 1e-3,
            "theta {theta:?}: a_y(9.98) = {}",
            y[499]
        );
    }
}

#[test]
fn measurement_noise_has_the_spec_variance() {
    let clean = NoiseFree::new(Box::new(PacejkaCar::new())).unwrap();
    let noisy = PacejkaCar::new();
    let theta = [-30.0, -1.0];
    let (_, y0) = simulate(&clean, &theta);
    let mut sum_sq = 0.0;
    let mut count = 0;
    for i in 0..20 {
        let mut record = noisy.spec().new_record();
        noisy
            .simulate(&theta, &mut experiment_rng(9, i), &mut record)
            .unwrap();
        for (a, b) in record.output(0).iter().zip(&y0) {
            sum_sq += (a - b).powi(2);
            count += 1;
        }
        // The input is measured without noise.
        assert!(
            record
                .input(0)
                .iter()
                .zip(&clean_input())
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }
    let var = sum_sq / count as f64;
    // 10,000 draws: standard error of the variance 0.01 * sqrt(2 / 1e4) = 1.4e-4.
    assert!((var - 0.01).abs() < 7e-4, "noise variance {var}");
}

fn clean_input() -> Vec<f64> {
    let car = NoiseFree::new(Box::new(PacejkaCar::new())).unwrap();
    simulate(&car, &[-35.0, -1.1]).0
}

#[test]
fn a_parameter_that_breaks_the_tire_model_is_reported_not_returned_as_nan() {
    let car = PacejkaCar::new();
    let mut record = car.spec().new_record();
    let err = car
        .simulate(&[-35.0, 0.0], &mut experiment_rng(0, 0), &mut record)
        .unwrap_err();
    let text = err.to_string();
    assert!(text.contains("diverged"), "{text}");
    assert!(text.contains("-35"), "{text}");
    assert!(text.contains("t = 0"), "{text}");
}
