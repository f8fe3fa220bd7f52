//! Cholesky factorization `A = L L'` of a small symmetric matrix, in place,
//! with the rank test stated by the caller, and the triangular solves.
//!
//! Matrices are row-major `n x n` slices; the factorization reads the lower
//! triangle of `A` and leaves `L` there, with the strictly upper triangle
//! zeroed. Each pivot is formed as `a_jj - l_j0^2 - l_j1^2 - ...`,
//! subtracting one product at a time, and each solve likewise.

/// The relative size under which a diagonal entry of R (or a Cholesky
/// pivot of the normal equations) marks a regressor as (numerically) a
/// linear combination of the previous ones: `|R_jj| <= RANK_TOLERANCE *
/// ||phi_j||`, i.e. the sine of the angle between column j and the span of
/// columns 0..j is below 1e-9 (a condition number near 1e9, where
/// least-squares coefficients stop being meaningful). The host's QR and the
/// microcontroller runtime's double-double Cholesky both test against it.
pub const RANK_TOLERANCE: f64 = 1e-9;

/// When a pivot counts as zero: the rank tolerance of a factorization.
///
/// `d_j` is the pivot before its square root (`a_jj` less the squares
/// already in row j), so `d_j / a_jj` is the squared sine of the angle
/// between column j and the span of the columns before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PivotRule {
    /// Refuse `d_j <= 0`: any positive definite matrix.
    Positive,
    /// Refuse `d_j <= tol^2 a_jj` (or `a_jj <= 0`): a column within angle
    /// `asin(tol)` of the previous ones is a rank deficiency. Normal
    /// equations use this with the QR rank check's tolerance.
    Angle(f64),
    /// Refuse `d_j <= tol * max_k a_kk`: small against the largest
    /// diagonal entry (a covariance whose feature does not vary).
    RelativeToLargest(f64),
    /// Accept a positive semi-definite matrix: a pivot in
    /// `[-tol * max_k |a_kk|, 0]` is rounding and gives a zero column (a
    /// state known exactly); only a pivot below that is refused.
    SemiDefinite(f64),
}

/// The factorization stopped at a pivot its [`PivotRule`] refuses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotPositiveDefinite {
    /// The column (0-based) whose pivot failed.
    pub column: usize,
    /// The pivot `d_j` before the square root (may be NaN).
    pub pivot: f64,
}

impl core::fmt::Display for NotPositiveDefinite {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "the matrix is not positive definite: pivot {} of column {} is refused",
            self.pivot, self.column
        )
    }
}

#[cfg(feature = "std")]
impl std::error::Error for NotPositiveDefinite {}

/// Factor the symmetric `n x n` matrix whose lower triangle is in `a`
/// (row-major) as `L L'`, leaving `L` in the lower triangle and zeros above.
///
/// ```
/// use twostage_kernels::cholesky::{PivotRule, cholesky_in_place};
/// // Two identical columns: rank 1, refused at column 1.
/// let mut a = [1.0, 1.0, 1.0, 1.0];
/// let e = cholesky_in_place(&mut a, 2, PivotRule::Angle(1e-3)).unwrap_err();
/// assert_eq!(e.column, 1);
/// // Semi-definite: accepted, with a zero column.
/// let mut a = [1.0, 1.0, 1.0, 1.0];
/// cholesky_in_place(&mut a, 2, PivotRule::SemiDefinite(1e-12))?;
/// assert_eq!(a, [1.0, 0.0, 1.0, 0.0]);
/// # Ok::<(), twostage_kernels::cholesky::NotPositiveDefinite>(())
/// ```
///
/// # Errors
/// The first pivot that `rule` refuses, or a NaN pivot; `a` is then
/// partly overwritten. A slice shorter than `n * n` is refused at column 0.
#[inline]
pub fn cholesky_in_place(
    a: &mut [f64],
    n: usize,
    rule: PivotRule,
) -> Result<(), NotPositiveDefinite> {
    let Some(a) = a.get_mut(..n * n) else {
        return Err(NotPositiveDefinite {
            column: 0,
            pivot: f64::NAN,
        });
    };
    let largest = match rule {
        PivotRule::RelativeToLargest(_) => (0..n).map(|j| a[j * n + j]).fold(0.0f64, f64::max),
        PivotRule::SemiDefinite(_) => (0..n)
            .map(|j| a[j * n + j].abs())
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE),
        _ => 0.0,
    };
    for j in 0..n {
        let diagonal = a[j * n + j];
        let mut d = diagonal;
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        let refused = match rule {
            PivotRule::Positive => d <= 0.0,
            PivotRule::Angle(tol) => d <= (tol * tol) * diagonal || diagonal <= 0.0,
            PivotRule::RelativeToLargest(tol) => d <= tol * largest,
            PivotRule::SemiDefinite(tol) => d < -tol * largest,
        };
        if d.is_nan() || refused {
            return Err(NotPositiveDefinite {
                column: j,
                pivot: d,
            });
        }
        let l = crate::sqrt(d.max(0.0));
        a[j * n + j] = l;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = if l > 0.0 { s / l } else { 0.0 };
        }
        for k in j + 1..n {
            a[j * n + k] = 0.0;
        }
    }
    Ok(())
}

/// Solve `L z = v` in place for the row-major lower-triangular `n x n`
/// `l` (only its lower triangle is read); `v` may be longer than `n`, its
/// tail is left alone.
///
/// ```
/// use twostage_kernels::cholesky::solve_lower_in_place;
/// let l = [2.0, 0.0, 1.0, 4.0];
/// let mut v = [2.0, 9.0];
/// solve_lower_in_place(&l[..], 2, &mut v);
/// assert_eq!(v, [1.0, 2.0]);
/// ```
///
/// `l` is any [`Values`](crate::Values): a slice, or an exported
/// estimator's bytes read in place.
#[inline]
pub fn solve_lower_in_place<L: crate::Values + ?Sized>(l: &L, n: usize, v: &mut [f64]) {
    for i in 0..n.min(v.len()) {
        let (done, rest) = v.split_at_mut(i);
        if let Some(vi) = rest.first_mut() {
            let mut s = *vi;
            for (k, vk) in done.iter().enumerate() {
                s -= l.at(i * n + k) * vk;
            }
            *vi = s / l.at(i * n + i);
        }
    }
}

/// Solve `L' x = z` in place for the row-major lower-triangular `n x n` `l`.
///
/// ```
/// use twostage_kernels::cholesky::solve_lower_transposed_in_place;
/// let l = [2.0, 0.0, 1.0, 4.0];
/// let mut z = [4.0, 8.0]; // L' = [[2, 1], [0, 4]]: x = (1, 2)
/// solve_lower_transposed_in_place(&l, 2, &mut z);
/// assert_eq!(z, [1.0, 2.0]);
/// ```
#[inline]
pub fn solve_lower_transposed_in_place(l: &[f64], n: usize, v: &mut [f64]) {
    for i in (0..n.min(v.len())).rev() {
        let mut s = v[i];
        for k in i + 1..n {
            s -= l[k * n + i] * v[k];
        }
        v[i] = s / l[i * n + i];
    }
}

/// Solve `L L' x = b` in place, `l` from [`cholesky_in_place`].
#[inline]
pub fn solve_cholesky_in_place(l: &[f64], n: usize, b: &mut [f64]) {
    solve_lower_in_place(l, n, b);
    solve_lower_transposed_in_place(l, n, b);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A = B B' + n I for a fixed B: symmetric positive definite.
    fn spd(n: usize) -> [f64; 36] {
        let mut a = [0.0; 36];
        for i in 0..n {
            for j in 0..n {
                let mut s = 0.0;
                for k in 0..n {
                    let b = |r: usize, c: usize| ((r * 7 + c * 3) % 5) as f64 - 2.0;
                    s += b(i, k) * b(j, k);
                }
                a[i * n + j] = s + if i == j { n as f64 } else { 0.0 };
            }
        }
        a
    }

    #[test]
    fn factor_times_its_transpose_is_the_matrix() {
        for n in 1..=6 {
            let a = spd(n);
            let mut l = a;
            cholesky_in_place(&mut l, n, PivotRule::Positive).unwrap();
            for i in 0..n {
                for j in 0..n {
                    let llt: f64 = (0..n).map(|k| l[i * n + k] * l[j * n + k]).sum();
                    assert!((llt - a[i * n + j]).abs() < 1e-12 * a[i * n + i].abs().max(1.0));
                    if j > i {
                        assert_eq!(l[i * n + j].to_bits(), 0);
                    }
                }
            }
        }
    }

    /// Against Gauss-Jordan elimination with partial pivoting, an
    /// independent algorithm.
    #[test]
    fn solves_agree_with_gauss_jordan() {
        let n = 5;
        let a = spd(n);
        let b = [1.0, -2.0, 0.5, 3.0, -1.0];
        let mut l = a;
        cholesky_in_place(&mut l, n, PivotRule::Angle(1e-3)).unwrap();
        let mut x = b;
        solve_cholesky_in_place(&l, n, &mut x);
        let mut m = [[0.0; 6]; 5];
        for i in 0..n {
            for j in 0..n {
                m[i][j] = a[i * n + j];
            }
            m[i][n] = b[i];
        }
        for c in 0..n {
            let p = (c..n)
                .max_by(|&r, &s| m[r][c].abs().total_cmp(&m[s][c].abs()))
                .unwrap();
            m.swap(c, p);
            let pivot_row = m[c];
            for (r, row) in m.iter_mut().enumerate().take(n) {
                if r != c {
                    let f = row[c] / pivot_row[c];
                    for (v, p) in row[c..=n].iter_mut().zip(&pivot_row[c..=n]) {
                        *v -= f * p;
                    }
                }
            }
        }
        for i in 0..n {
            let gj = m[i][n] / m[i][i];
            assert!(
                (x[i] - gj).abs() < 1e-12 * gj.abs().max(1.0),
                "{i}: {} vs {gj}",
                x[i]
            );
        }
    }

    #[test]
    fn rules_refuse_what_they_say() {
        // Columns at an angle of about 1e-4: refused by Angle(1e-3), accepted
        // by Positive.
        let e = 1e-4;
        let a = [1.0, 1.0, 1.0, 1.0 + e * e];
        assert_eq!(
            cholesky_in_place(&mut a.clone(), 2, PivotRule::Angle(1e-3))
                .unwrap_err()
                .column,
            1
        );
        assert!(cholesky_in_place(&mut a.clone(), 2, PivotRule::Positive).is_ok());
        // A feature with variance 1e-14 of the largest.
        let a = [1.0, 0.0, 0.0, 1e-14];
        assert!(cholesky_in_place(&mut a.clone(), 2, PivotRule::RelativeToLargest(1e-12)).is_err());
        assert!(cholesky_in_place(&mut a.clone(), 2, PivotRule::RelativeToLargest(1e-15)).is_ok());
        // Indefinite: refused by every rule, semi-definite included.
        let a = [1.0, 2.0, 2.0, 1.0];
        for rule in [
            PivotRule::Positive,
            PivotRule::Angle(1e-3),
            PivotRule::RelativeToLargest(1e-12),
            PivotRule::SemiDefinite(1e-12),
        ] {
            assert!(
                cholesky_in_place(&mut a.clone(), 2, rule).is_err(),
                "{rule:?}"
            );
        }
        // NaN and a short slice.
        assert!(cholesky_in_place(&mut [f64::NAN], 1, PivotRule::Positive).is_err());
        assert!(cholesky_in_place(&mut [1.0; 3], 2, PivotRule::Positive).is_err());
    }
}
