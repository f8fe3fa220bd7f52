//! Double-double arithmetic: a number as the unevaluated sum `hi + lo` of
//! two doubles, about 106 bits of precision (Dekker, "A floating-point
//! technique for extending the available precision", Numer. Math. 18,
//! 1971; Hida, Li and Bailey, "Library for double-double and quad-double
//! arithmetic", 2000, for the addition, division and square root).
//!
//! Stage 1's normal equations square the regressors' condition number; a
//! stream cannot keep the record for the host's iterative refinement, so
//! it keeps the sums and solves in double-double instead. The products
//! use Dekker's split, not a fused multiply-add, so every platform (with
//! or without an FMA) computes the same bits.

/// `hi + lo` with `|lo| <= ulp(hi) / 2`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Dd {
    pub(crate) hi: f64,
    pub(crate) lo: f64,
}

/// `a + b = s + e` exactly (Knuth).
#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// `a + b = s + e` exactly, for `|a| >= |b|`.
#[inline]
fn quick_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

/// `a = hi + lo` with each half holding 26 bits: the halves that
/// [`accumulate`] multiplies exactly.
#[inline]
pub(crate) fn split(a: f64) -> (f64, f64) {
    const SPLITTER: f64 = 134_217_729.0; // 2^27 + 1
    let t = SPLITTER * a;
    let hi = t - (t - a);
    (hi, a - hi)
}

/// `a b = p + e` exactly (for `|a b|` well inside the range).
#[inline]
pub(crate) fn two_prod(a: f64, b: f64) -> Dd {
    let p = a * b;
    let (ah, al) = split(a);
    let (bh, bl) = split(b);
    let e = ((ah * bh - p) + ah * bl + al * bh) + al * bl;
    Dd { hi: p, lo: e }
}

/// `acc + a b` with the product exact and the sum compensated, for
/// factors already split into halves ([`split`]): the running sum
/// stays in `hi`, every rounding error goes to `lo` (the Dot2 of Ogita,
/// Rump and Oishi, "Accurate sum and dot product", SIAM J. Sci. Comput.
/// 26, 2005: as accurate as twice the working precision, at about half
/// the cost of a double-double addition). [`Dd::normalized`] before use.
#[inline]
pub(crate) fn accumulate(
    acc: Dd,
    a: f64,
    (ah, al): (f64, f64),
    (bh, bl): (f64, f64),
    b: f64,
) -> Dd {
    let p = a * b;
    let e = ((ah * bh - p) + ah * bl + al * bh) + al * bl;
    let (s, t) = two_sum(acc.hi, p);
    Dd {
        hi: s,
        lo: acc.lo + (t + e),
    }
}

impl Dd {
    /// The same number with `|lo| <= ulp(hi) / 2`.
    pub(crate) fn normalized(self) -> Dd {
        let (hi, lo) = two_sum(self.hi, self.lo);
        Dd { hi, lo }
    }

    pub(crate) fn from_f64(v: f64) -> Dd {
        Dd { hi: v, lo: 0.0 }
    }

    pub(crate) fn to_f64(self) -> f64 {
        self.hi + self.lo
    }

    pub(crate) fn add(self, o: Dd) -> Dd {
        let (s1, s2) = two_sum(self.hi, o.hi);
        let (t1, t2) = two_sum(self.lo, o.lo);
        let (s1, s2) = quick_two_sum(s1, s2 + t1);
        let (hi, lo) = quick_two_sum(s1, s2 + t2);
        Dd { hi, lo }
    }

    pub(crate) fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }

    pub(crate) fn sub(self, o: Dd) -> Dd {
        self.add(o.neg())
    }

    pub(crate) fn mul(self, o: Dd) -> Dd {
        let p = two_prod(self.hi, o.hi);
        let (hi, lo) = quick_two_sum(p.hi, p.lo + (self.hi * o.lo + self.lo * o.hi));
        Dd { hi, lo }
    }

    fn mul_f64(self, b: f64) -> Dd {
        let p = two_prod(self.hi, b);
        let (hi, lo) = quick_two_sum(p.hi, p.lo + self.lo * b);
        Dd { hi, lo }
    }

    pub(crate) fn div(self, o: Dd) -> Dd {
        let q1 = self.hi / o.hi;
        let r = self.sub(o.mul_f64(q1));
        let q2 = r.hi / o.hi;
        let r = r.sub(o.mul_f64(q2));
        let q3 = r.hi / o.hi;
        let (hi, lo) = quick_two_sum(q1, q2);
        Dd { hi, lo }.add(Dd::from_f64(q3))
    }

    /// The square root of a positive number (one Newton step from the
    /// double's root, which doubles its 53 bits).
    pub(crate) fn sqrt(self) -> Dd {
        if self.hi <= 0.0 {
            return Dd::default();
        }
        let s = libm::sqrt(self.hi);
        let residual = self.sub(two_prod(s, s));
        let (hi, lo) = quick_two_sum(s, residual.hi / (2.0 * s));
        Dd { hi, lo }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::float_cmp)]
    use super::*;

    /// Exact checks on dyadic numbers, where the error terms are known.
    #[test]
    fn products_and_sums_keep_what_a_double_loses() {
        let a = 1.0 + f64::EPSILON; // 1 + 2^-52
        let p = two_prod(a, a); // 1 + 2^-51 + 2^-104
        assert_eq!(p.hi, 1.0 + 2.0 * f64::EPSILON);
        assert_eq!(p.lo, f64::EPSILON * f64::EPSILON);
        // (1 + 2^-60) - 1 = 2^-60 exactly.
        let x = Dd::from_f64(1.0).add(Dd::from_f64(2f64.powi(-60)));
        assert_eq!(x.sub(Dd::from_f64(1.0)).to_f64(), 2f64.powi(-60));
    }

    #[test]
    fn compensated_products_sum_as_double_double_does() {
        // Terms whose sum cancels to a tiny remainder: the plain double
        // sum loses it, the compensated one keeps what double-double keeps.
        let terms = [
            (1e8 + 1.0 / 3.0, 3.0),
            (-1e8, 3.0),
            (2f64.powi(-40), 1.0 + f64::EPSILON),
        ];
        let (mut exact, mut compensated) = (Dd::default(), Dd::default());
        for (a, b) in terms {
            exact = exact.add(two_prod(a, b));
            compensated = accumulate(compensated, a, split(a), split(b), b);
        }
        let compensated = compensated.normalized();
        // Dot2's bound: within (n eps)^2 of the sum of |terms| (6e8 here).
        let magnitude: f64 = terms.iter().map(|(a, b)| (a * b).abs()).sum();
        let error = compensated.sub(exact).to_f64().abs();
        assert!(error < 1e-30 * magnitude, "{compensated:?} vs {exact:?}");
        let plain: f64 = terms.iter().map(|(a, b)| a * b).sum();
        assert!((plain - exact.to_f64()).abs() > 1e-9);
    }

    #[test]
    fn division_and_root_agree_with_their_inverses_to_double_double() {
        // 1/3 and sqrt(2): q * 3 and r * r come back to 1 and 2 within 1e-30.
        let third = Dd::from_f64(1.0).div(Dd::from_f64(3.0));
        let back = third.mul(Dd::from_f64(3.0)).sub(Dd::from_f64(1.0));
        assert!(back.to_f64().abs() < 1e-30, "{back:?}");
        let root = Dd::from_f64(2.0).sqrt();
        let back = root.mul(root).sub(Dd::from_f64(2.0));
        assert!(back.to_f64().abs() < 1e-30, "{back:?}");
        // The high part is the correctly rounded double.
        assert_eq!(root.hi, 2f64.sqrt());
        assert_eq!(third.hi, 1.0 / 3.0);
        assert_eq!(Dd::from_f64(-1.0).sqrt(), Dd::default());
    }
}
