//! The benchmark's Kalman likelihood against the direct Gaussian density.

// A panic is how a test fails; reference linear algebra reads best with indices.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

use twostage_baselines::{BenchmarkStateSpace, benchmark_kalman};
use twostage_models::IoData;

/// ln N(y; mean, Sigma) by Cholesky: the density of the whole record at
/// once, built from the state-space moments, with no filtering at all.
fn direct_log_density(theta: f64, u: &[f64], y: &[f64]) -> f64 {
    let m = BenchmarkStateSpace::at(theta);
    let n = y.len();
    // x(k) = sum_{j<k} A^(k-1-j) (B u(j) + w(j)): mean and covariances.
    let mul = |a: [[f64; 2]; 2], b: [[f64; 2]; 2]| -> [[f64; 2]; 2] {
        [
            [
                a[0][0] * b[0][0] + a[0][1] * b[1][0],
                a[0][0] * b[0][1] + a[0][1] * b[1][1],
            ],
            [
                a[1][0] * b[0][0] + a[1][1] * b[1][0],
                a[1][0] * b[0][1] + a[1][1] * b[1][1],
            ],
        ]
    };
    let mut powers = vec![[[1.0, 0.0], [0.0, 1.0]]];
    for k in 1..n {
        powers.push(mul(m.a, powers[k - 1]));
    }
    let mean: Vec<f64> = (0..n)
        .map(|k| {
            (0..k)
                .map(|j| {
                    let p = powers[k - 1 - j];
                    (p[1][0] * m.b[0] + p[1][1] * m.b[1]) * u[j]
                })
                .sum()
        })
        .collect();
    // Cov(x2(k), x2(l)) = q sum_{j < min(k,l)} (A^(k-1-j) A^(l-1-j)')[1][1].
    let mut cov = vec![vec![0.0; n]; n];
    for k in 0..n {
        for l in 0..n {
            let mut c = 0.0;
            for j in 0..k.min(l) {
                let (pk, pl) = (powers[k - 1 - j], powers[l - 1 - j]);
                c += m.q * (pk[1][0] * pl[1][0] + pk[1][1] * pl[1][1]);
            }
            cov[k][l] = c + if k == l { m.r } else { 0.0 };
        }
    }
    // Cholesky and the log-density.
    let mut lower = vec![vec![0.0; n]; n];
    for j in 0..n {
        let d = cov[j][j] - (0..j).map(|k| lower[j][k] * lower[j][k]).sum::<f64>();
        lower[j][j] = d.sqrt();
        for i in j + 1..n {
            lower[i][j] =
                (cov[i][j] - (0..j).map(|k| lower[i][k] * lower[j][k]).sum::<f64>()) / lower[j][j];
        }
    }
    let mut z = vec![0.0; n];
    for i in 0..n {
        z[i] = (y[i] - mean[i] - (0..i).map(|k| lower[i][k] * z[k]).sum::<f64>()) / lower[i][i];
    }
    let log_det: f64 = (0..n).map(|i| lower[i][i].ln()).sum::<f64>() * 2.0;
    -0.5 * (n as f64 * (2.0 * std::f64::consts::PI).ln()
        + log_det
        + z.iter().map(|v| v * v).sum::<f64>())
}

#[test]
fn the_filter_likelihood_equals_the_direct_gaussian_density() {
    let u = [0.3, -1.2, 0.8, 0.05, -0.4, 1.1, 0.7];
    let y = [0.1, -0.2, 0.9, -1.3, 0.4, 0.0, 2.1];
    let record = IoData::siso(&u, &y).unwrap();
    for theta in [-0.85, -0.2, 0.0, 0.45, 0.9] {
        let filtered = benchmark_kalman(theta, &record).unwrap().log_likelihood;
        let direct = direct_log_density(theta, &u, &y);
        assert!(
            (filtered - direct).abs() < 1e-10 * direct.abs(),
            "theta {theta}: {filtered} vs {direct}"
        );
    }
}

#[test]
fn mimo_and_non_finite_records_are_refused() {
    let record = IoData::zeros(10, 2, 1);
    let e = benchmark_kalman(0.1, &record).unwrap_err();
    assert!(
        matches!(&e, twostage_baselines::BaselineError::Shape { found, .. } if found == "2 and 1"),
        "{e}"
    );
    let mut nan = IoData::zeros(10, 1, 1);
    nan.output_mut(0)[3] = f64::NAN;
    let e = benchmark_kalman(0.1, &nan).unwrap_err();
    assert!(
        e.to_string().contains("non-finite value (NaN) at sample 3"),
        "the bad sample is named: {e}"
    );
}
