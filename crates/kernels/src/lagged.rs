//! Least squares on lagged signals through the normal equations, without
//! forming the regressor matrix.
//!
//! The entries of eq. (2)'s `sum_t phi(t) phi(t)'` and `sum_t phi(t) y(t)`
//! are lagged correlations of the signals: `sum_{t=start}^{N-1} a(t - la)
//! b(t - lb)` depends on the pair of signals, the lag difference and a few
//! terms at the window's ends. One full-length dot product per (signal
//! pair, lag difference) therefore serves every entry, and the `n x n`
//! system is solved by [`crate::cholesky`] with the angle test, which
//! declines an ill-conditioned problem instead of answering it badly.

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
    /// The Cholesky pivot of this column failed the angle test: the
    /// regressors are (nearly) collinear, so a QR solve should decide.
    IllConditioned {
        /// The regressor column whose pivot failed.
        column: usize,
    },
}

/// The buffers of one problem with `n` columns over `s` signals and lags
/// up to `max_lag`: `table` holds `s * s * (max_lag + 1)` memoized
/// correlations, `gram` `n * n` and `solution` `n` values.
pub struct LaggedBuffers<'a> {
    /// Memo of full-length correlations; overwritten.
    pub table: &'a mut [f64],
    /// The normal matrix, then its Cholesky factor.
    pub gram: &'a mut [f64],
    /// The right-hand side, then the coefficients.
    pub solution: &'a mut [f64],
}

/// Assemble and solve the normal equations of the regression of
/// `signals[0]` at lag 0 on `columns`, over samples `start..N`.
///
/// `dot` computes a full-length correlation `sum_k a[k] b[k]` over equally
/// long slices: the host passes a SIMD version, a microcontroller
/// [`crate::dot`]. `tolerance` is the smallest accepted sine of the angle
/// between a column and the span of the previous ones
/// ([`PivotRule::Angle`]).
///
/// ```
/// use twostage_kernels::lagged::{LaggedBuffers, LaggedColumn, lagged_least_squares};
/// // y(t) = 0.5 y(t-1) + u(t-1), exactly: the fit recovers (0.5, 1).
/// let u: Vec<f64> = (0..50).map(|k| ((k * 37 % 11) as f64) - 5.0).collect();
/// let mut y = vec![0.0; 50];
/// for t in 1..50 { y[t] = 0.5 * y[t - 1] + u[t - 1]; }
/// let columns = [LaggedColumn { signal: 0, lag: 1 }, LaggedColumn { signal: 1, lag: 1 }];
/// let (mut table, mut gram, mut alpha) = ([0.0; 8], [0.0; 4], [0.0; 2]);
/// let buffers = LaggedBuffers { table: &mut table, gram: &mut gram, solution: &mut alpha };
/// lagged_least_squares(&[&y, &u], &columns, 1, 1, 1e-3, twostage_kernels::dot, buffers)?;
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
    tolerance: f64,
    dot: impl Fn(&[f64], &[f64]) -> f64,
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
            table[slot] = dot(&sa[d..], &sb[..len - d]);
        }
        // Terms tau = t - lb outside [start - lb, N - 1 - lb].
        let head = dot(&sa[d..d + start - b.lag], &sb[..start - b.lag]);
        let tail = dot(&sa[len - b.lag + d..len], &sb[len - b.lag..len - d]);
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
    cholesky_in_place(gram, n, PivotRule::Angle(tolerance))
        .map_err(|e| LaggedDeclined::IllConditioned { column: e.column })?;
    solve_cholesky_in_place(gram, n, solution);
    if solution[..n].iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(LaggedDeclined::NotFinite)
    }
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
            1e-6,
            crate::dot,
            LaggedBuffers {
                table: &mut table,
                gram: &mut gram,
                solution: &mut alpha,
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
                1e-3,
                crate::dot,
                LaggedBuffers {
                    table: &mut table,
                    gram: &mut gram,
                    solution: &mut alpha,
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
}
