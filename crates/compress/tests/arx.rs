//! ARX compression against known coefficients and an independent solver.

// A panic is how a test fails; reference linear algebra reads best with indices.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

use ndarray::{Array2, ArrayView2, ShapeBuilder};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use twostage_compress::InvalidSetting;
use twostage_compress::{Arx, CompressError, Compressor, Workspace};

fn noise(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
}

/// Simulate y(t) = sum a_k y(t-k) + sum b_l u(t-delay-l) + e(t).
fn simulate_arx(a: &[f64], b: &[f64], delay: usize, u: &[f64], e: &[f64]) -> Vec<f64> {
    let n = u.len();
    let mut y = vec![0.0; n];
    for t in 0..n {
        let mut v = e[t];
        for (k, ak) in a.iter().enumerate() {
            if t > k {
                v += ak * y[t - k - 1];
            }
        }
        for (l, bl) in b.iter().enumerate() {
            if t >= delay + l {
                v += bl * u[t - delay - l];
            }
        }
        y[t] = v;
    }
    y
}

fn column(v: &[f64]) -> Array2<f64> {
    Array2::from_shape_vec((v.len(), 1), v.to_vec()).unwrap()
}

/// Least squares by the normal equations and Gauss-Jordan elimination with
/// partial pivoting: a second algorithm, independent of faer and of QR.
fn normal_equations(phi: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let n = phi[0].len();
    let mut m = vec![vec![0.0; n + 1]; n];
    for (row, yt) in phi.iter().zip(y) {
        for i in 0..n {
            for j in 0..n {
                m[i][j] += row[i] * row[j];
            }
            m[i][n] += row[i] * yt;
        }
    }
    for c in 0..n {
        let p = (c..n)
            .max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))
            .unwrap();
        m.swap(c, p);
        for r in 0..n {
            if r != c {
                let f = m[r][c] / m[c][c];
                for k in c..=n {
                    m[r][k] -= f * m[c][k];
                }
            }
        }
    }
    (0..n).map(|i| m[i][n] / m[i][i]).collect()
}

#[test]
fn recovers_known_coefficients_from_noise_free_data() {
    let a = [0.6, -0.3, 0.1];
    let b = [1.0, -0.5, 0.25];
    for delay in [0, 1, 3] {
        let u = noise(400, 1);
        let y = simulate_arx(&a, &b, delay, &u, &[0.0; 400]);
        let arx = Arx::new(3, 3).unwrap().with_delay(delay).unwrap();
        let alpha = arx.compress(column(&u).view(), column(&y).view()).unwrap();
        let want: Vec<f64> = a.iter().chain(&b).copied().collect();
        for (g, w) in alpha.iter().zip(&want) {
            assert!(
                (g - w).abs() < 1e-12,
                "delay {delay}: {alpha:?} != {want:?}"
            );
        }
    }
}

#[test]
fn recovers_miso_coefficients_for_each_output_of_a_mimo_record() {
    let n = 300;
    let (u1, u2) = (noise(n, 2), noise(n, 3));
    // y1 = 0.5 y1(t-1) + 2 u1(t-1) - u2(t-1); y2 = -0.4 y2(t-1) + 0.3 u1(t-1) + 0.7 u2(t-1).
    let mut y = Array2::<f64>::zeros((n, 2));
    for t in 1..n {
        y[[t, 0]] = 0.5 * y[[t - 1, 0]] + 2.0 * u1[t - 1] - u2[t - 1];
        y[[t, 1]] = -0.4 * y[[t - 1, 1]] + 0.3 * u1[t - 1] + 0.7 * u2[t - 1];
    }
    let mut u = Array2::<f64>::zeros((n, 2));
    for t in 0..n {
        u[[t, 0]] = u1[t];
        u[[t, 1]] = u2[t];
    }
    let arx = Arx::new(1, 1).unwrap().with_signals(2, 2).unwrap();
    assert_eq!(
        arx.feature_names(),
        [
            "a1[y1]",
            "b1[y1<-u1]",
            "b1[y1<-u2]",
            "a1[y2]",
            "b1[y2<-u1]",
            "b1[y2<-u2]"
        ]
    );
    let alpha = arx.compress(u.view(), y.view()).unwrap();
    for (g, w) in alpha.iter().zip([0.5, 2.0, -1.0, -0.4, 0.3, 0.7]) {
        assert!((g - w).abs() < 1e-12, "{alpha:?}");
    }
}

#[test]
fn agrees_with_the_normal_equations_on_noisy_data() {
    // A noisy, well-conditioned record: the least-squares solutions of QR
    // and of the normal equations agree to rounding.
    let n = 1000;
    let u = noise(n, 4);
    let e = noise(n, 5);
    let y = simulate_arx(&[0.5, 0.2], &[1.0, 0.3], 1, &u, &e);
    let (na, nb) = (5, 5);
    let arx = Arx::new(na, nb).unwrap();
    let alpha = arx.compress(column(&u).view(), column(&y).view()).unwrap();
    let start = arx.first_sample();
    let phi: Vec<Vec<f64>> = (start..n)
        .map(|t| {
            (1..=na)
                .map(|k| y[t - k])
                .chain((1..=nb).map(|k| u[t - k]))
                .collect()
        })
        .collect();
    let reference = normal_equations(&phi, &y[start..]);
    for (g, w) in alpha.iter().zip(&reference) {
        assert!((g - w).abs() < 1e-10, "{alpha:?}\n{reference:?}");
    }
}

#[test]
fn a_reused_workspace_gives_the_same_bits_as_a_fresh_one() {
    let arx = Arx::new(4, 4).unwrap();
    let mut work = Workspace::new();
    let mut alpha = vec![0.0; 8];
    for (n, seed) in [(500, 6), (120, 7), (500, 8), (2000, 9)] {
        let u = noise(n, seed);
        let y = simulate_arx(&[0.3], &[1.0], 1, &u, &noise(n, seed + 100));
        let (u, y) = (column(&u), column(&y));
        arx.compress_into(u.view(), y.view(), &mut work, &mut alpha)
            .unwrap();
        let fresh = arx.compress(u.view(), y.view()).unwrap();
        assert_eq!(
            alpha.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            fresh.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}

fn compress_error(arx: &Arx, u: &[f64], y: &[f64]) -> CompressError {
    arx.compress(column(u).view(), column(y).view())
        .unwrap_err()
}

#[test]
fn degenerate_records_are_refused_with_their_cause() {
    let n = 200;
    let u = noise(n, 10);
    let y = simulate_arx(&[0.5], &[1.0], 1, &u, &noise(n, 11));
    let arx = Arx::new(2, 2).unwrap();

    let err = compress_error(&arx, &[0.7; 200], &y).to_string();
    assert!(err.contains("u is constant (0.7)"), "{err}");

    let err = compress_error(&arx, &u, &[0.0; 200]).to_string();
    assert!(err.contains("y is zero over the whole record"), "{err}");

    let err = compress_error(&arx, &u[..5], &y[..5]).to_string();
    assert!(err.contains("5 samples, too short for ARX(2, 2)"), "{err}");
    assert!(err.contains("at least 6"), "{err}");

    // A single sinusoid spans only two dimensions: three input lags of it
    // are linearly dependent.
    let sine: Vec<f64> = (0..n).map(|k| (0.3 * k as f64).sin()).collect();
    let err = compress_error(&Arx::new(0, 3).unwrap(), &sine, &y).to_string();
    assert!(err.contains("regressor b3[y<-u]"), "{err}");

    let mut bad = y.clone();
    bad[17] = f64::NAN;
    let err = compress_error(&arx, &u, &bad);
    assert!(
        matches!(err, CompressError::NonFinite { index: 17, .. }),
        "{err}"
    );

    let err = arx
        .compress(column(&u).view(), column(&y[..100]).view())
        .unwrap_err();
    assert!(matches!(err, CompressError::LengthMismatch { .. }), "{err}");
    let wide = Array2::<f64>::zeros((n, 2));
    let err = arx.compress(wide.view(), column(&y).view()).unwrap_err();
    assert!(matches!(err, CompressError::ShapeMismatch { .. }), "{err}");
    let mut short = [0.0; 3];
    let err = arx
        .compress_into(
            column(&u).view(),
            column(&y).view(),
            &mut Workspace::new(),
            &mut short,
        )
        .unwrap_err();
    assert!(matches!(
        err,
        CompressError::BufferLength {
            expected: 4,
            got: 3
        }
    ));
}

#[test]
fn invalid_orders_are_refused() {
    let setting = |result: Result<Arx, CompressError>| match result {
        Err(CompressError::InvalidSetting(InvalidSetting { name, value, .. })) => (name, value),
        other => panic!("expected an invalid setting, got {other:?}"),
    };
    assert_eq!(setting(Arx::new(0, 0)), ("na + nb", "0".into()));
    assert_eq!(setting(Arx::new(65, 1)), ("na", "65".into()));
    let one = Arx::new(1, 1).unwrap();
    assert_eq!(setting(one.with_delay(100)), ("delay", "100".into()));
    assert_eq!(setting(one.with_signals(1, 0)), ("outputs", "0".into()));
}

#[test]
fn strided_views_are_read_correctly() {
    // A row-major N x 2 array: its columns are strided, not contiguous.
    let n = 300;
    let u = noise(n, 12);
    let y = simulate_arx(&[0.2], &[0.9], 1, &u, &[0.0; 300]);
    let both = Array2::from_shape_fn((n, 2), |(t, j)| if j == 0 { u[t] } else { y[t] });
    let u_view: ArrayView2<'_, f64> = both.slice(ndarray::s![.., 0..1]);
    let y_view: ArrayView2<'_, f64> = both.slice(ndarray::s![.., 1..2]);
    let alpha = Arx::new(1, 1).unwrap().compress(u_view, y_view).unwrap();
    assert!((alpha[0] - 0.2).abs() < 1e-12 && (alpha[1] - 0.9).abs() < 1e-12);
}

fn fast_and_qr(arx: &Arx, u: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> (Vec<f64>, Vec<f64>) {
    let mut work = Workspace::new();
    let mut fast = vec![0.0; arx.n_features()];
    arx.compress_fast_into(u, y, &mut work, &mut fast).unwrap();
    (fast, arx.compress(u, y).unwrap())
}

fn assert_agree(fast: &[f64], qr: &[f64], what: &str) {
    for (f, q) in fast.iter().zip(qr) {
        assert!(
            (f - q).abs() <= 1e-9 * q.abs().max(1.0),
            "{what}: fast {fast:?}\n qr {qr:?}"
        );
    }
}

#[test]
fn the_fast_path_agrees_with_qr_on_noisy_records() {
    for (seed, (na, nb, delay)) in [
        (20, (5, 5, 1)),
        (21, (4, 4, 1)),
        (22, (2, 3, 0)),
        (23, (1, 6, 3)),
        (24, (6, 0, 1)),
    ] {
        let n = 1000;
        let u = noise(n, seed);
        let y = simulate_arx(&[0.7, -0.2, 0.05], &[1.0, 0.4], 1, &u, &noise(n, seed + 50));
        let arx = Arx::new(na, nb).unwrap().with_delay(delay).unwrap();
        let (fast, qr) = fast_and_qr(&arx, column(&u).view(), column(&y).view());
        assert_agree(&fast, &qr, &arx.to_string());
    }
}

#[test]
fn the_fast_path_agrees_with_qr_on_mimo_records() {
    let n = 600;
    let u = Array2::from_shape_fn((n, 2), |(t, j)| noise(n, 30 + j as u64)[t]);
    let mut y = Array2::<f64>::zeros((n, 2));
    let e = noise(2 * n, 40);
    for t in 1..n {
        y[[t, 0]] = 0.5 * y[[t - 1, 0]] + u[[t - 1, 0]] - 0.3 * u[[t - 1, 1]] + 0.1 * e[t];
        y[[t, 1]] = -0.2 * y[[t - 1, 1]] + 0.8 * u[[t - 1, 1]] + 0.1 * e[n + t];
    }
    // Column-major copies, so the fast path gets contiguous signals.
    let u_f = Array2::from_shape_vec((n, 2).f(), u.t().iter().copied().collect()).unwrap();
    let y_f = Array2::from_shape_vec((n, 2).f(), y.t().iter().copied().collect()).unwrap();
    let arx = Arx::new(2, 2).unwrap().with_signals(2, 2).unwrap();
    let (fast, qr) = fast_and_qr(&arx, u_f.view(), y_f.view());
    assert_agree(&fast, &qr, "MIMO");
}

#[test]
fn the_fast_path_falls_back_to_qr_for_its_errors_and_hard_cases() {
    let n = 300;
    let u = noise(n, 60);
    let y = simulate_arx(&[0.5], &[1.0], 1, &u, &noise(n, 61));
    let arx = Arx::new(2, 2).unwrap();
    let mut work = Workspace::new();
    let mut alpha = [0.0; 4];
    let err = arx
        .compress_fast_into(
            column(&[0.7; 300]).view(),
            column(&y).view(),
            &mut work,
            &mut alpha,
        )
        .unwrap_err();
    assert!(err.to_string().contains("u is constant"), "{err}");
    let mut bad = y.clone();
    bad[100] = f64::INFINITY;
    let err = arx
        .compress_fast_into(
            column(&u).view(),
            column(&bad).view(),
            &mut work,
            &mut alpha,
        )
        .unwrap_err();
    assert!(
        matches!(err, CompressError::NonFinite { index: 100, .. }),
        "{err}"
    );
    // A smooth input: neighbouring input lags are nearly collinear, so the
    // fast path refines its answer or hands over to QR; either way it is
    // QR's to 1e-9.
    let smooth: Vec<f64> = (0..n)
        .map(|k| (0.02 * k as f64).sin() + 0.3 * (0.05 * k as f64).cos())
        .collect();
    let ys = simulate_arx(&[0.9], &[0.1, 0.05], 1, &smooth, &noise(n, 62));
    let arx = Arx::new(2, 3).unwrap();
    let (fast, qr) = fast_and_qr(&arx, column(&smooth).view(), column(&ys).view());
    assert_agree(&fast, &qr, "smooth input");
}

#[test]
fn a_diverging_record_is_refused_as_unstable_not_as_poorly_excited() {
    let n = 400;
    let u = Array2::from_shape_fn((n, 1), |(k, _)| ((k * 7919) % 13) as f64 / 6.0 - 1.0);
    let mut y = Array2::<f64>::zeros((n, 1));
    for t in 2..n {
        // Poles at 1.6 and 0.5: the output grows like 1.6^t (1e81 at the end).
        y[[t, 0]] = 2.1 * y[[t - 1, 0]] - 0.8 * y[[t - 2, 0]] + u[[t - 1, 0]];
    }
    let e = Arx::new(5, 5)
        .unwrap()
        .compress(u.view(), y.view())
        .unwrap_err();
    assert!(e.to_string().contains("unstable"), "{e}");
}
