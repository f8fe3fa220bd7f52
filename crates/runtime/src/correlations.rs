//! Stage 1's normal equations kept as lagged correlations: every entry of
//! eq. (2)'s `sum_t phi(t) phi(t)'` and `sum_t phi(t) y(t)` is a full-length
//! correlation `R_xz(d) = sum_tau x(tau + d) z(tau)` of two signals at a
//! lag difference d, less a few products at the record's ends (the
//! kernels' `lagged` module assembles the host's the same way). A stream
//! therefore updates one sum per (signal pair, lag difference) per sample,
//! far fewer than the entries of the normal matrix (24 against 65 for
//! ARX(5, 5)), and keeps the first and the last few samples for the ends.
//!
//! Each product is exact and each sum compensated
//! ([`crate::dd::accumulate`]); the ends are subtracted in double-double.

use crate::dd::{self, Dd, split, two_prod};

/// The shape of a stream's correlations: `signals` = outputs then inputs,
/// `lags` = the largest regressor lag (the first sample of the window).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shape {
    pub(crate) outputs: usize,
    pub(crate) signals: usize,
    pub(crate) lags: usize,
}

/// Where the stream keeps what it has seen, as slices of the workspace.
pub(crate) struct Memory<'w> {
    /// Per signal, lags 1..=L, most recent first: (value, its two halves).
    pub(crate) history: &'w mut [f64],
    /// Per signal, its first L samples.
    pub(crate) first: &'w mut [f64],
    /// Per (x, z, d): R_xz(d) as (hi, lo).
    pub(crate) sums: &'w mut [f64],
}

impl Shape {
    pub(crate) fn history_words(&self) -> usize {
        3 * self.signals * self.lags
    }
    pub(crate) fn first_words(&self) -> usize {
        self.signals * self.lags
    }
    pub(crate) fn sum_words(&self) -> usize {
        2 * self.signals * self.signals * (self.lags + 1)
    }

    /// Two different outputs never meet in one regression.
    fn needed(&self, x: usize, z: usize) -> bool {
        !(x < self.outputs && z < self.outputs && x != z)
    }

    fn slot(&self, x: usize, z: usize, d: usize) -> usize {
        (x * self.signals + z) * (self.lags + 1) + d
    }

    /// Take sample `t`: `current(s)` is signal s's value now.
    pub(crate) fn push(&self, t: usize, current: impl Fn(usize) -> f64, m: &mut Memory<'_>) {
        let lags = self.lags;
        let past = |history: &[f64], s: usize, k: usize| -> (f64, (f64, f64)) {
            let at = 3 * (s * lags + k - 1);
            let v = |i: usize| history.get(at + i).copied().unwrap_or(f64::NAN);
            (v(0), (v(1), v(2)))
        };
        for x in 0..self.signals {
            let cx = current(x);
            let sx = split(cx);
            for z in (0..self.signals).filter(|z| self.needed(x, *z)) {
                for d in 0..=lags.min(t) {
                    let (zv, sz) = if d == 0 {
                        let cz = current(z);
                        (cz, split(cz))
                    } else {
                        past(m.history, z, d)
                    };
                    let k = self.slot(x, z, d);
                    store(m.sums, k, dd::accumulate(load(m.sums, k), cx, sx, sz, zv));
                }
            }
        }
        if lags == 0 {
            return;
        }
        for s in 0..self.signals {
            let now = current(s);
            if t < lags
                && let Some(slot) = m.first.get_mut(s * lags + t)
            {
                *slot = now;
            }
            if let Some(block) = m.history.get_mut(3 * s * lags..3 * (s + 1) * lags) {
                block.copy_within(..3 * (lags - 1), 3);
                let (hi, lo) = split(now);
                if let Some(head) = block.get_mut(..3) {
                    head.copy_from_slice(&[now, hi, lo]);
                }
            }
        }
    }

    /// Signal s at sample `index` of a record of `n` samples, from the
    /// first samples or the recent ones (every index a finish asks for is
    /// in one of them).
    fn value(&self, m: &Memory<'_>, s: usize, index: usize, n: usize) -> f64 {
        let lags = self.lags;
        if index < lags {
            m.first.get(s * lags + index).copied()
        } else {
            let k = n - index;
            m.history.get(3 * (s * lags + k - 1)).copied()
        }
        .unwrap_or(f64::NAN)
    }

    /// `sum_{t = L}^{n-1} x(t - la) z(t - lb)` for a record of `n > L`
    /// samples.
    pub(crate) fn entry(
        &self,
        m: &Memory<'_>,
        n: usize,
        a: (usize, usize),
        b: (usize, usize),
    ) -> Dd {
        let ((x, la), (z, lb)) = if a.1 <= b.1 { (a, b) } else { (b, a) };
        let d = lb - la;
        let mut sum = load(m.sums, self.slot(x, z, d)).normalized();
        // The full correlation runs over tau = 0..n-d; the window over
        // tau = L-lb..n-lb.
        let ends = (0..self.lags - lb).chain(n - lb..n - d);
        for tau in ends {
            let p = two_prod(self.value(m, x, tau + d, n), self.value(m, z, tau, n));
            sum = sum.sub(p);
        }
        sum
    }
}

#[inline]
pub(crate) fn load(sums: &[f64], k: usize) -> Dd {
    Dd {
        hi: sums.get(2 * k).copied().unwrap_or(f64::NAN),
        lo: sums.get(2 * k + 1).copied().unwrap_or(f64::NAN),
    }
}

#[inline]
pub(crate) fn store(sums: &mut [f64], k: usize, v: Dd) {
    if let Some(pair) = sums.get_mut(2 * k..2 * k + 2) {
        pair.copy_from_slice(&[v.hi, v.lo]);
    }
}
