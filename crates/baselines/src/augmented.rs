//! The benchmark of eq. (5) with theta as a third state (Section 5.1):
//!
//! ```text
//! x1(k+1) = x1(k) / 2 + u(k) + v11(k)
//! x2(k+1) = (1 - x3^2) sin(50 x3^2) x1(k) - x3 x2(k) + x3 / (1 + x3^2) u(k) + v12(k)
//! x3(k+1) = x3(k) + w(k),   w ~ N(0, 1e-6)
//! y(k)    = x2(k) + v2(k)
//! ```

// 3 x 3 matrix algebra reads best with indices.
#![allow(clippy::needless_range_loop)]

use twostage_kernels::cholesky::{PivotRule, cholesky_in_place};
use twostage_models::{MEASUREMENT_NOISE_VARIANCE, PROCESS_NOISE_VARIANCE};

/// Variance of the random walk of theta in the augmented state.
pub const THETA_RANDOM_WALK_VARIANCE: f64 = 1e-6;

/// A 3 x 3 matrix, row-major.
pub(crate) type M3 = [[f64; 3]; 3];

/// The state transition of the benchmark augmented with theta as a third
/// state (Section 5.1 of the paper), without its noises: what the EKF and
/// UKF propagate.
///
/// ```
/// // theta = 0 makes x2 forget everything: x2(k+1) = 0.
/// assert_eq!(twostage_baselines::transition([1.0, 2.0, 0.0], 3.0), [3.5, 0.0, 0.0]);
/// ```
pub fn transition(z: [f64; 3], u: f64) -> [f64; 3] {
    let (x1, x2, th) = (z[0], z[1], z[2]);
    let t2 = th * th;
    [
        0.5 * x1 + u,
        (1.0 - t2) * (50.0 * t2).sin() * x1 - th * x2 + th / (1.0 + t2) * u,
        th,
    ]
}

/// The Jacobian of [`transition`] with respect to the state (the EKF's
/// linearization; a test checks it against finite differences).
pub fn transition_jacobian(z: [f64; 3], u: f64) -> M3 {
    let (x1, x2, th) = (z[0], z[1], z[2]);
    let t2 = th * th;
    let (s, c) = (50.0 * t2).sin_cos();
    let a = (1.0 - t2) * s;
    let da = -2.0 * th * s + (1.0 - t2) * c * 100.0 * th;
    let db = (1.0 - t2) / ((1.0 + t2) * (1.0 + t2));
    [
        [0.5, 0.0, 0.0],
        [a, -th, da * x1 - x2 + db * u],
        [0.0, 0.0, 1.0],
    ]
}

/// Process noise covariance diag(1, 1, theta_walk) (the paper: 1e-6).
pub(crate) fn process_noise(theta_walk: f64) -> M3 {
    [
        [PROCESS_NOISE_VARIANCE, 0.0, 0.0],
        [0.0, PROCESS_NOISE_VARIANCE, 0.0],
        [0.0, 0.0, theta_walk],
    ]
}

/// Measurement noise variance 0.1.
pub(crate) const MEASUREMENT_VARIANCE: f64 = MEASUREMENT_NOISE_VARIANCE;

/// The paper's initial covariances of the estimation error.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum InitialCovariance {
    /// Eq. (6): diag(0.1, 0.1, 0.5), a large initial variance of theta.
    Eq6,
    /// Eq. (7): diag(0.1, 0.1, 0.01), a small one.
    Eq7,
    /// Any user-given symmetric positive semi-definite matrix.
    Custom([[f64; 3]; 3]),
}

impl InitialCovariance {
    /// The matrix.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        match self {
            Self::Eq6 => [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.5]],
            Self::Eq7 => [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.01]],
            Self::Custom(m) => *m,
        }
    }
}

pub(crate) fn mul(a: &M3, b: &M3) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

pub(crate) fn transpose(a: &M3) -> M3 {
    let mut t = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] = a[j][i];
        }
    }
    t
}

pub(crate) fn add(a: &M3, b: &M3) -> M3 {
    let mut c = *a;
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] += b[i][j];
        }
    }
    c
}

/// Symmetrize, to keep rounding from breaking the symmetry of a covariance.
pub(crate) fn symmetrize(a: &mut M3) {
    for i in 0..3 {
        for j in 0..i {
            let m = 0.5 * (a[i][j] + a[j][i]);
            a[i][j] = m;
            a[j][i] = m;
        }
    }
}

/// Lower Cholesky factor of a positive semi-definite 3 x 3 matrix; zero
/// pivots (a state known exactly) give zero columns. `None` if a pivot is
/// negative beyond rounding.
pub(crate) fn cholesky(a: &M3) -> Option<M3> {
    let mut flat: [f64; 9] = std::array::from_fn(|k| a[k / 3][k % 3]);
    cholesky_in_place(&mut flat, 3, PivotRule::SemiDefinite(1e-12)).ok()?;
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| flat[i * 3 + j])
    }))
}
