//! Least squares on lagged signals through the normal equations, without
//! forming the regressor matrix.
//!
//! The entries of eq. (2)'s `sum_t phi(t) phi(t)'` and `sum_t phi(t) y(t)`
//! are lagged correlations of the signals: `sum_{t=start}^{N-1} a(t - la)
//! b(t - lb)` depends on the pair of signals, the lag difference and a few
//! terms at the window's ends. One full-length dot product per (signal
//! pair, lag difference) therefore serves every entry, and the `n x n`
//! system is solved by [`crate::cholesky`] with the angle test.
//!
//! Normal equations square the condition number. A well-conditioned
//! problem is answered directly; a moderately ill-conditioned one (a
//! smooth input makes neighbouring lags nearly collinear) is answered by
//! the corrected semi-normal equations: the Cholesky factor of the normal
//! matrix, then steps of iterative refinement `x += (R'R)^-1 Phi'(y - Phi
//! x)` with the residual formed from the signals (Bjorck, "Numerical
//! Methods for Least Squares Problems", SIAM 1996, Section 2.8.5 and
//! 6.6.5), each step shrinking the error by about `cond(Phi)^2 eps`. A
//! worse one is declined, for QR to decide.

use crate::VectorOps;
use crate::cholesky::{PivotRule, cholesky_in_place, solve_cholesky_in_place};

/// One regressor column: which signal at which lag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaggedColumn {
    /// Index into the signals (by convention 0 is the fitted output).
    pub signal: usize,
    /// The lag in samples.
    pub lag: usize,
}

/// Why [`lagged_least_squares`] did not answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LaggedDeclined {
    /// The signals' lengths differ, are shorter than the lags, or the
    /// buffers are too small for the problem.
    Shape,
    /// A normal-equation entry is not finite.
    NotFinite,
    /// The Cholesky pivot of this column failed the angle test, or the
    /// refinement did not settle: the regressors are (nearly) collinear,
    /// so a QR solve should decide.
    IllConditioned {
        /// The regressor column whose pivot failed (the columns' count when
        /// the refinement did not settle).
        column: usize,
    },
}

/// How collinear the regressors may be, as the sine of the angle between a
/// column and the span of the columns before it (the Cholesky pivot
/// `L_jj / sqrt(G_jj)`, the QR rank check's measure).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conditioning {
    /// Down to this sine the normal equations are answered directly.
    pub direct: f64,
    /// Down to this sine (at most `direct`) they are answered with
    /// iterative refinement; below it, declined.
    pub refined: f64,
}

/// The first sample of an ARX regression with `na` output lags and `nb`
/// input lags from `delay` on: the first whose regressors all lie inside
/// the record, `max(na, delay + nb - 1)` (just `na` without input lags).
///
/// ```
/// use twostage_kernels::lagged::arx_first_sample;
/// assert_eq!(arx_first_sample(2, 2, 1), 2);
/// assert_eq!(arx_first_sample(1, 2, 3), 4);
/// assert_eq!(arx_first_sample(3, 0, 1), 3);
/// ```
pub fn arx_first_sample(na: usize, nb: usize, delay: usize) -> usize {
    let input_reach = if nb == 0 { 0 } else { delay + nb - 1 };
    na.max(input_reach)
}

/// The most refinement steps; a problem that needs more is declined.
pub const MAX_REFINEMENT_STEPS: usize = 4;

/// A refinement has settled when its last correction is at most this
/// share of the largest coefficient. The correction is the error of the
/// iterate before it, so the iterate after it is off by the contraction
/// factor (`cond^2 eps`, 1e-5 for the car's chicane) times that, or by the
/// rounding floor of a residual formed in double precision (5e-11 there):
/// within the 1e-9 agreement with QR that the callers promise.
pub const SETTLED: f64 = 1e-9;

/// The buffers of one problem with `n` columns over `s` signals of N
/// samples and lags up to `max_lag`: `table` holds `s * s * (max_lag + 1)`
/// memoized correlations, `gram` `n * n` and `solution` `n` values. The
/// refinement needs `residual` of `N - start` and `correction` of `n`
/// values; with shorter ones (a stream that never holds the record) a
/// problem that needs refining is declined.
pub struct LaggedBuffers<'a> {
    /// Memo of full-length correlations; overwritten.
    pub table: &'a mut [f64],
    /// The normal matrix, then its Cholesky factor.
    pub gram: &'a mut [f64],
    /// The right-hand side, then the coefficients.
    pub solution: &'a mut [f64],
    /// The residual `y - Phi x` of a refinement step.
    pub residual: &'a mut [f64],
    /// The correction of a refinement step.
    pub correction: &'a mut [f64],
}

/// Assemble and solve the normal equations of the regression of
/// `signals[0]` at lag 0 on `columns`, over samples `start..N`.
///
/// `ops` computes the correlations and the residuals: the host passes its
/// SIMD versions, a microcontroller [`crate::PlainOps`]. `conditioning` says how collinear the columns may be
/// for a direct answer and for a refined one.
///
/// ```
/// use twostage_kernels::lagged::{Conditioning, LaggedBuffers, LaggedColumn, lagged_least_squares};
/// // y(t) = 0.5 y(t-1) + u(t-1), exactly: the fit recovers (0.5, 1).
/// let u: Vec<f64> = (0..50).map(|k| ((k * 37 % 11) as f64) - 5.0).collect();
/// let mut y = vec![0.0; 50];
/// for t in 1..50 { y[t] = 0.5 * y[t - 1] + u[t - 1]; }
/// let columns = [LaggedColumn { signal: 0, lag: 1 }, LaggedColumn { signal: 1, lag: 1 }];
/// let (mut table, mut gram, mut alpha) = ([0.0; 8], [0.0; 4], [0.0; 2]);
/// let (mut residual, mut correction) = ([0.0; 49], [0.0; 2]);
/// let buffers = LaggedBuffers {
///     table: &mut table, gram: &mut gram, solution: &mut alpha,
///     residual: &mut residual, correction: &mut correction,
/// };
/// let conditioning = Conditioning { direct: 1e-3, refined: 1e-6 };
/// lagged_least_squares(&[&y, &u], &columns, 1, 1, conditioning, &twostage_kernels::PlainOps, buffers)?;
/// assert!((alpha[0] - 0.5).abs() < 1e-12 && (alpha[1] - 1.0).abs() < 1e-12);
/// # Ok::<(), twostage_kernels::lagged::LaggedDeclined>(())
/// ```
///
/// # Errors
/// [`LaggedDeclined`]: the caller should then solve by QR, which gives the
/// exact answer or the precise reason.
#[inline]
pub fn lagged_least_squares(
    signals: &[&[f64]],
    columns: &[LaggedColumn],
    start: usize,
    max_lag: usize,
    conditioning: Conditioning,
    ops: &impl VectorOps,
    buffers: LaggedBuffers<'_>,
) -> Result<(), LaggedDeclined> {
    let n = columns.len();
    let n_signals = signals.len();
    let lags = max_lag + 1;
    let len = signals.first().map_or(0, |s| s.len());
    let LaggedBuffers {
        table,
        gram,
        solution,
        residual,
        correction,
    } = buffers;
    let shape_ok = len >= lags
        && start >= max_lag
        && start <= len
        && signals.iter().all(|s| s.len() == len)
        && columns
            .iter()
            .all(|c| c.signal < n_signals && c.lag <= max_lag)
        && table.len() >= n_signals * n_signals * lags
        && gram.len() >= n * n
        && solution.len() >= n;
    if !shape_ok {
        return Err(LaggedDeclined::Shape);
    }
    table.fill(f64::NAN);
    // sum_{t = start}^{N-1} a(t - la) b(t - lb), for la <= lb, from the
    // full-length correlation at lag d = lb - la (computed once per signal
    // pair and lag) minus the few terms outside the window.
    let mut windowed = |a: LaggedColumn, b: LaggedColumn| -> f64 {
        let (a, b) = if a.lag <= b.lag { (a, b) } else { (b, a) };
        let d = b.lag - a.lag;
        let (sa, sb) = (signals[a.signal], signals[b.signal]);
        let slot = (a.signal * n_signals + b.signal) * lags + d;
        if table[slot].is_nan() {
            table[slot] = ops.dot(&sa[d..], &sb[..len - d]);
        }
        // Terms tau = t - lb outside [start - lb, N - 1 - lb]: at most
        // max_lag of them, summed plainly.
        let head = crate::dot(&sa[d..d + start - b.lag], &sb[..start - b.lag]);
        let tail = crate::dot(&sa[len - b.lag + d..len], &sb[len - b.lag..len - d]);
        table[slot] - head - tail
    };
    let target = LaggedColumn { signal: 0, lag: 0 };
    for i in 0..n {
        for j in 0..=i {
            let g = windowed(columns[i], columns[j]);
            gram[i * n + j] = g;
            gram[j * n + i] = g;
        }
        solution[i] = windowed(columns[i], target);
    }
    if !gram[..n * n]
        .iter()
        .chain(&solution[..n])
        .all(|v| v.is_finite())
    {
        return Err(LaggedDeclined::NotFinite);
    }
    let floor = conditioning.refined.min(conditioning.direct);
    cholesky_in_place(gram, n, PivotRule::Angle(floor))
        .map_err(|e| LaggedDeclined::IllConditioned { column: e.column })?;
    solve_cholesky_in_place(gram, n, solution);
    if !solution[..n].iter().all(|v| v.is_finite()) {
        return Err(LaggedDeclined::NotFinite);
    }
    // Row j of L holds G_jj = sum_k L_jk^2, so the pivot's sine needs no
    // copy of the normal matrix.
    let direct = (0..n).all(|j| {
        let row = &gram[j * n..j * n + j + 1];
        let norm_squared: f64 = row.iter().map(|l| l * l).sum();
        row[j] * row[j] > conditioning.direct * conditioning.direct * norm_squared
    });
    if direct {
        return Ok(());
    }
    let rows = len - start;
    let (Some(residual), Some(correction)) = (residual.get_mut(..rows), correction.get_mut(..n))
    else {
        return Err(LaggedDeclined::IllConditioned { column: n });
    };
    for _ in 0..MAX_REFINEMENT_STEPS {
        residual.copy_from_slice(&signals[0][start..]);
        for (column, x) in columns.iter().zip(solution.iter()) {
            let lagged = &signals[column.signal][start - column.lag..len - column.lag];
            ops.subtract_scaled(residual, *x, lagged);
        }
        for (column, c) in columns.iter().zip(correction.iter_mut()) {
            *c = ops.dot(
                &signals[column.signal][start - column.lag..len - column.lag],
                residual,
            );
        }
        solve_cholesky_in_place(gram, n, correction);
        let (mut step, mut size) = (0.0f64, 0.0f64);
        for (x, c) in solution[..n].iter_mut().zip(correction.iter()) {
            *x += c;
            step = step.max(c.abs());
            size = size.max(x.abs());
        }
        if !step.is_finite() {
            return Err(LaggedDeclined::NotFinite);
        }
        if step <= SETTLED * size {
            return Ok(());
        }
    }
    Err(LaggedDeclined::IllConditioned { column: n })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normal equations formed from explicit regressor rows, the
    /// textbook way, against the lagged assembly.
    #[test]
    fn lagged_entries_equal_explicit_sums() {
        let n_samples = 40;
        let y: [f64; 40] = core::array::from_fn(|k| ((k * 13 % 7) as f64) - 3.0 + 0.1 * k as f64);
        let u: [f64; 40] = core::array::from_fn(|k| ((k * 5 % 9) as f64) - 4.0);
        let columns = [
            LaggedColumn { signal: 0, lag: 1 },
            LaggedColumn { signal: 0, lag: 2 },
            LaggedColumn { signal: 1, lag: 1 },
            LaggedColumn { signal: 1, lag: 3 },
        ];
        let start = 3;
        let (mut table, mut gram, mut alpha) = ([0.0; 16], [0.0; 16], [0.0; 4]);
        lagged_least_squares(
            &[&y, &u],
            &columns,
            start,
            3,
            Conditioning {
                direct: 1e-6,
                refined: 1e-6,
            },
            &crate::PlainOps,
            LaggedBuffers {
                table: &mut table,
                gram: &mut gram,
                solution: &mut alpha,
                residual: &mut [],
                correction: &mut [],
            },
        )
        .unwrap();
        // Explicit normal equations, solved by the same Cholesky.
        let signals = [&y[..], &u[..]];
        let mut g = [0.0; 16];
        let mut r = [0.0; 4];
        for t in start..n_samples {
            let phi: [f64; 4] =
                core::array::from_fn(|c| signals[columns[c].signal][t - columns[c].lag]);
            for i in 0..4 {
                for j in 0..4 {
                    g[i * 4 + j] += phi[i] * phi[j];
                }
                r[i] += phi[i] * y[t];
            }
        }
        cholesky_in_place(&mut g, 4, PivotRule::Positive).unwrap();
        solve_cholesky_in_place(&g, 4, &mut r);
        for (a, b) in alpha.iter().zip(&r) {
            assert!(
                (a - b).abs() < 1e-10 * b.abs().max(1.0),
                "{alpha:?} vs {r:?}"
            );
        }
    }

    #[test]
    fn declines_bad_shapes_and_collinear_columns() {
        let y = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let columns = [
            LaggedColumn { signal: 0, lag: 1 },
            LaggedColumn { signal: 0, lag: 1 },
        ];
        let (mut table, mut gram, mut alpha) = ([0.0; 2], [0.0; 4], [0.0; 2]);
        let mut run = |signals: &[&[f64]], cols: &[LaggedColumn]| {
            lagged_least_squares(
                signals,
                cols,
                1,
                1,
                Conditioning {
                    direct: 1e-3,
                    refined: 1e-6,
                },
                &crate::PlainOps,
                LaggedBuffers {
                    table: &mut table,
                    gram: &mut gram,
                    solution: &mut alpha,
                    residual: &mut [0.0; 6],
                    correction: &mut [0.0; 2],
                },
            )
        };
        assert_eq!(
            run(&[&y], &columns),
            Err(LaggedDeclined::IllConditioned { column: 1 })
        );
        assert_eq!(
            run(&[&y, &y[..3]], &columns[..1]),
            Err(LaggedDeclined::Shape)
        );
        assert_eq!(
            run(&[&y], &[LaggedColumn { signal: 2, lag: 1 }]),
            Err(LaggedDeclined::Shape)
        );
        assert_eq!(
            run(&[&[1.0, f64::INFINITY, 1.0]], &columns[..1]),
            Err(LaggedDeclined::NotFinite)
        );
    }

    /// Least squares by Householder QR of the explicit regressor matrix
    /// (rows x n, row-major), a second algorithm: backward stable, so its
    /// error is the problem's own sensitivity.
    fn householder_least_squares(a: &mut [f64], b: &mut [f64], rows: usize, n: usize) -> [f64; 8] {
        for k in 0..n {
            let norm = (k..rows)
                .map(|i| a[i * n + k] * a[i * n + k])
                .sum::<f64>()
                .sqrt();
            let alpha = if a[k * n + k] > 0.0 { -norm } else { norm };
            let mut v: [f64; 600] = [0.0; 600];
            for i in k..rows {
                v[i] = a[i * n + k];
            }
            v[k] -= alpha;
            let vv: f64 = (k..rows).map(|i| v[i] * v[i]).sum();
            for j in k..n {
                let s: f64 = (k..rows).map(|i| v[i] * a[i * n + j]).sum();
                for i in k..rows {
                    a[i * n + j] -= 2.0 * s / vv * v[i];
                }
            }
            let s: f64 = (k..rows).map(|i| v[i] * b[i]).sum();
            for i in k..rows {
                b[i] -= 2.0 * s / vv * v[i];
            }
        }
        let mut x = [0.0; 8];
        for k in (0..n).rev() {
            let s: f64 = (k + 1..n).map(|j| a[k * n + j] * x[j]).sum();
            x[k] = (b[k] - s) / a[k * n + k];
        }
        x
    }

    #[test]
    fn refinement_answers_smooth_inputs_as_qr_does() {
        // A smooth input makes its neighbouring lags nearly collinear
        // (sines below 1e-3, as with the car's chicane): the direct answer is
        // declined, the refined one agrees with Householder QR.
        const N: usize = 500;
        let u: [f64; N] = core::array::from_fn(|k| {
            let t = k as f64 * 0.05;
            libm::sin(0.7 * t) + 0.4 * libm::cos(1.9 * t)
        });
        let mut y = [0.0; N];
        let mut noise = 0.3f64;
        for t in 2..N {
            noise = (noise * 3.9 * (1.0 - noise)).clamp(0.01, 0.99);
            y[t] = 1.6 * y[t - 1] - 0.64 * y[t - 2] + 0.5 * u[t - 1] + 0.01 * (noise - 0.5);
        }
        let columns: [LaggedColumn; 8] = core::array::from_fn(|c| LaggedColumn {
            signal: c / 4,
            lag: c % 4 + 1,
        });
        let (start, n) = (4, 8);
        let run = |conditioning: Conditioning, alpha: &mut [f64; 8]| {
            let (mut table, mut gram) = ([0.0; 20], [0.0; 64]);
            let (mut residual, mut correction) = ([0.0; N], [0.0; 8]);
            lagged_least_squares(
                &[&y, &u],
                &columns,
                start,
                4,
                conditioning,
                &crate::PlainOps,
                LaggedBuffers {
                    table: &mut table,
                    gram: &mut gram,
                    solution: alpha,
                    residual: &mut residual,
                    correction: &mut correction,
                },
            )
        };
        let mut alpha = [0.0; 8];
        let direct_only = Conditioning {
            direct: 1e-3,
            refined: 1e-3,
        };
        assert!(matches!(
            run(direct_only, &mut alpha),
            Err(LaggedDeclined::IllConditioned { .. })
        ));
        let refined = Conditioning {
            direct: 1e-3,
            refined: 1e-7,
        };
        run(refined, &mut alpha).unwrap();
        let rows = N - start;
        let mut a = [0.0; 500 * 8];
        let mut b = [0.0; 500];
        let signals = [&y[..], &u[..]];
        for r in 0..rows {
            for (c, column) in columns.iter().enumerate() {
                a[r * n + c] = signals[column.signal][start + r - column.lag];
            }
            b[r] = y[start + r];
        }
        let qr = householder_least_squares(&mut a, &mut b, rows, n);
        for (x, q) in alpha.iter().zip(&qr) {
            assert!(
                (x - q).abs() <= 1e-9 * q.abs().max(1.0),
                "refined {alpha:?}\n QR {qr:?}"
            );
        }
        // Without room for the residual, the refinement is declined.
        let (mut table, mut gram) = ([0.0; 20], [0.0; 64]);
        let declined = lagged_least_squares(
            &[&y, &u],
            &columns,
            start,
            4,
            refined,
            &crate::PlainOps,
            LaggedBuffers {
                table: &mut table,
                gram: &mut gram,
                solution: &mut alpha,
                residual: &mut [0.0; 10],
                correction: &mut [0.0; 8],
            },
        );
        assert_eq!(declined, Err(LaggedDeclined::IllConditioned { column: 8 }));
    }
}
