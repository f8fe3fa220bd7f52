//! Polynomial NARX against known coefficients and an independent solver.

// A panic is how a test fails; reference linear algebra reads best with indices.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twostage_compress::{Compressor, Narx, Workspace, signal_rms};

fn uniform(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

fn column(v: &[f64]) -> Array2<f64> {
    Array2::from_shape_vec((v.len(), 1), v.to_vec()).unwrap()
}

/// y(t) = c + 0.5 y(t-1) + u(t-1) + 0.1 y(t-1) u(t-1) - 0.3 u(t-1)^2 + e(t)
fn simulate(u: &[f64], e: &[f64], c: f64) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for t in 1..u.len() {
        let (y1, u1) = (y[t - 1], u[t - 1]);
        y[t] = c + 0.5 * y1 + u1 + 0.1 * y1 * u1 - 0.3 * u1 * u1 + e[t];
    }
    y
}

#[test]
fn recovers_known_coefficients_and_names_them() {
    let n = 300;
    let u = uniform(n, 1);
    let y = simulate(&u, &vec![0.0; n], 0.2);
    let narx = Narx::new(1, 1, 2).unwrap();
    assert_eq!(
        narx.feature_names(),
        [
            "1[y]",
            "y(t-1)[y]",
            "u(t-1)[y]",
            "y(t-1)*y(t-1)[y]",
            "y(t-1)*u(t-1)[y]",
            "u(t-1)*u(t-1)[y]"
        ]
    );
    let alpha = narx.compress(column(&u).view(), column(&y).view()).unwrap();
    for (g, w) in alpha.iter().zip([0.2, 0.5, 1.0, 0.0, 0.1, -0.3]) {
        assert!((g - w).abs() < 1e-10, "{alpha:?}");
    }
}

#[test]
fn scaled_coefficients_transform_as_the_monomials_do() {
    // With y scaled by sy and u by su, the model y/sy = sum c'_m prod(x/s)
    // has c'_m = c_m prod(s) / sy.
    let n = 300;
    let u = uniform(n, 2);
    let y = simulate(&u, &vec![0.0; n], 0.0);
    let (su, sy) = (0.5, 2.0);
    let narx = Narx::new(1, 1, 2)
        .unwrap()
        .with_scales(&[su], &[sy])
        .unwrap();
    let alpha = narx.compress(column(&u).view(), column(&y).view()).unwrap();
    let want = [
        0.0,
        0.5 * sy / sy,
        su / sy,
        0.0,
        0.1 * sy * su / sy,
        -0.3 * su * su / sy,
    ];
    for (g, w) in alpha.iter().zip(want) {
        assert!((g - w).abs() < 1e-10, "{alpha:?} vs {want:?}");
    }
}

#[test]
fn pure_powers_fit_a_cubic_input_nonlinearity() {
    let n = 400;
    let u = uniform(n, 3);
    let mut y = vec![0.0; n];
    for t in 1..n {
        y[t] = 0.4 * y[t - 1] + u[t - 1] + 0.2 * u[t - 1].powi(3);
    }
    let narx = Narx::new(1, 1, 3).unwrap().pure_powers(true);
    assert_eq!(narx.n_features(), 7);
    let alpha = narx.compress(column(&u).view(), column(&y).view()).unwrap();
    // [1, y, u, y^2, u^2, y^3, u^3]
    for (g, w) in alpha.iter().zip([0.0, 0.4, 1.0, 0.0, 0.0, 0.0, 0.2]) {
        assert!((g - w).abs() < 1e-10, "{alpha:?}");
    }
}

#[test]
fn agrees_with_the_normal_equations_on_noisy_data() {
    let n = 800;
    let u = uniform(n, 4);
    let e: Vec<f64> = uniform(n, 5).iter().map(|v| 0.05 * v).collect();
    let y = simulate(&u, &e, 0.1);
    let narx = Narx::new(2, 2, 2).unwrap();
    let alpha = narx.compress(column(&u).view(), column(&y).view()).unwrap();
    // Regressors built independently: [1, y1, y2, u1, u2, then products i <= j].
    let phi: Vec<Vec<f64>> = (2..n)
        .map(|t| {
            let v = [y[t - 1], y[t - 2], u[t - 1], u[t - 2]];
            let mut row = vec![1.0];
            row.extend(v);
            for i in 0..4 {
                for j in i..4 {
                    row.push(v[i] * v[j]);
                }
            }
            row
        })
        .collect();
    let k = phi[0].len();
    assert_eq!(k, alpha.len());
    let mut m = vec![vec![0.0; k + 1]; k];
    for (row, yt) in phi.iter().zip(&y[2..]) {
        for i in 0..k {
            for j in 0..k {
                m[i][j] += row[i] * row[j];
            }
            m[i][k] += row[i] * yt;
        }
    }
    for c in 0..k {
        let p = (c..k)
            .max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))
            .unwrap();
        m.swap(c, p);
        for r in 0..k {
            if r != c {
                let f = m[r][c] / m[c][c];
                for j in c..=k {
                    m[r][j] -= f * m[c][j];
                }
            }
        }
    }
    for i in 0..k {
        let want = m[i][k] / m[i][i];
        assert!(
            (alpha[i] - want).abs() < 1e-9,
            "coefficient {i}: {} vs {want}",
            alpha[i]
        );
    }
}

#[test]
fn a_binary_input_cannot_carry_squares_and_says_so() {
    let n = 200;
    let u: Vec<f64> = uniform(n, 6).iter().map(|v| v.signum()).collect();
    let y = simulate(&u, &uniform(n, 7), 0.0);
    let err = Narx::new(1, 1, 2)
        .unwrap()
        .compress(column(&u).view(), column(&y).view())
        .unwrap_err()
        .to_string();
    assert!(err.contains("u(t-1)*u(t-1)"), "{err}");
    let mut work = Workspace::new();
    let mut alpha = vec![0.0; 3];
    assert!(
        Narx::new(1, 1, 2)
            .unwrap()
            .compress_into(column(&u).view(), column(&y).view(), &mut work, &mut alpha)
            .is_err()
    );
}

#[test]
fn invalid_structures_and_scales_are_refused() {
    assert!(Narx::new(0, 0, 2).is_err());
    assert!(Narx::new(1, 1, 0).is_err());
    assert!(Narx::new(1, 1, 6).is_err());
    assert!(Narx::new(17, 1, 1).is_err());
    assert!(
        Narx::new(1, 1, 2)
            .unwrap()
            .with_scales(&[0.0], &[1.0])
            .is_err()
    );
    assert!(
        Narx::new(1, 1, 2)
            .unwrap()
            .with_scales(&[1.0], &[])
            .is_err()
    );
    let rms = signal_rms(column(&[0.0, 0.0]).view());
    assert!(
        (rms[0] - 1.0).abs() < 1e-15,
        "an all-zero signal keeps scale 1"
    );
}
