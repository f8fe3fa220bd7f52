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
//! ([`crate::dd::accumulate`]); the ends are subtracted in double-double,
//! and the packed normal equations solved in it ([`solve`]).

use twostage_kernels::cholesky::RANK_TOLERANCE;

use crate::dd::{self, Dd, split, two_prod};

/// The shape of a stream's correlations: `signals` = outputs then inputs,
/// `lags` = the largest regressor lag (the first sample of the window).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shape {
    pub(crate) outputs: usize,
    pub(crate) signals: usize,
    pub(crate) lags: usize,
}

/// Where a stream keeps the samples it still needs.
pub(crate) enum Past<'w> {
    /// A whole record: per signal its first L samples, and its last L in
    /// a ring (sample i at slot i mod L, so that a push moves nothing) as
    /// (value, its two halves).
    Record {
        first: &'w mut [f64],
        last: &'w mut [f64],
    },
    /// A window of the last `length` samples: per signal a ring of them
    /// (sample i at slot i mod length), which the sums forget a sample
    /// from as it leaves.
    Window { ring: &'w mut [f64], length: usize },
}

/// Where the stream keeps what it has seen, as slices of the workspace.
pub(crate) struct Memory<'w> {
    pub(crate) past: Past<'w>,
    /// Per (x, z, d): R_xz(d) as (hi, lo).
    pub(crate) sums: &'w mut [f64],
}

impl Memory<'_> {
    /// The ring's length: L for a record, the window's for a window
    /// (at least 1).
    fn ring_len(&self, shape: &Shape) -> usize {
        match self.past {
            Past::Record { .. } => shape.lags,
            Past::Window { length, .. } => length,
        }
        .max(1)
    }

    /// Signal s at absolute sample `i` (one the memory still holds), with
    /// its two halves.
    pub(crate) fn sample(&self, shape: &Shape, s: usize, i: usize) -> (f64, (f64, f64)) {
        self.at_slot(shape, s, i % self.ring_len(shape))
    }

    /// Signal s in ring slot `slot`, with its two halves.
    fn at_slot(&self, shape: &Shape, s: usize, slot: usize) -> (f64, (f64, f64)) {
        match &self.past {
            Past::Record { last, .. } => {
                let at = 3 * (s * shape.lags + slot);
                let v = |k: usize| last.get(at + k).copied().unwrap_or(f64::NAN);
                (v(0), (v(1), v(2)))
            }
            Past::Window { ring, length } => {
                let v = ring.get(s * length + slot).copied().unwrap_or(f64::NAN);
                (v, split(v))
            }
        }
    }

    /// Keep signal s's value `now` at absolute sample `t`, whose ring slot
    /// is `slot`.
    fn keep(&mut self, shape: &Shape, s: usize, t: usize, slot: usize, now: f64) {
        let lags = shape.lags;
        match &mut self.past {
            Past::Record { first, last } => {
                if lags == 0 {
                    return;
                }
                if t < lags
                    && let Some(slot) = first.get_mut(s * lags + t)
                {
                    *slot = now;
                }
                let at = 3 * (s * lags + slot);
                if let Some(kept) = last.get_mut(at..at + 3) {
                    let (hi, lo) = split(now);
                    kept.copy_from_slice(&[now, hi, lo]);
                }
            }
            Past::Window { ring, length } => {
                if let Some(kept) = ring.get_mut(s * *length + slot) {
                    *kept = now;
                }
            }
        }
    }

    /// Signal s at sample `index` of the `n` samples the sums hold (of a
    /// window, counted from its start): every index a finish asks for is
    /// among the first or the last L, which the memory holds.
    fn value(&self, shape: &Shape, s: usize, index: usize, n: usize, pushed: usize) -> f64 {
        match &self.past {
            Past::Record { first, .. } if index < shape.lags => first
                .get(s * shape.lags + index)
                .copied()
                .unwrap_or(f64::NAN),
            _ => self.sample(shape, s, pushed - n + index).0,
        }
    }
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

    /// Take sample `t`: `current(s)` is signal s's value now. A window
    /// that is full first forgets its oldest sample.
    pub(crate) fn push(&self, t: usize, current: impl Fn(usize) -> f64, m: &mut Memory<'_>) {
        let window = match m.past {
            Past::Window { length, .. } => Some(length),
            Past::Record { .. } => None,
        };
        if let Some(length) = window
            && t >= length
        {
            self.forget(t - length, m);
        }
        // Ring slots step back from sample t's without a division each.
        let ring = m.ring_len(self);
        let now = t % ring;
        let back = |d: usize| if now >= d { now - d } else { now + ring - d };
        // One loop per kind of memory, each with its reads inlined.
        let Memory { past, sums } = m;
        match past {
            Past::Record { last, .. } => {
                let lags = self.lags;
                let past = |z: usize, d: usize| {
                    let at = 3 * (z * lags + back(d));
                    let v = |k: usize| last.get(at + k).copied().unwrap_or(f64::NAN);
                    (v(0), (v(1), v(2)))
                };
                self.gain(t, &current, past, false, sums);
            }
            Past::Window { ring, length } => {
                let length = *length;
                let past = |z: usize, d: usize| {
                    let v = ring.get(z * length + back(d)).copied().unwrap_or(f64::NAN);
                    (v, split(v))
                };
                // Sums that also lose products are kept normalized, so
                // that their error stays a double-double's however long
                // the window slides.
                self.gain(t, &current, past, true, sums);
            }
        }
        for s in 0..self.signals {
            m.keep(self, s, t, now, current(s));
        }
    }

    /// Keep sample `t` without any products: a stage 1 that keeps no
    /// lagged sums (the linearized car's) still keeps a window's samples
    /// to summarize its input at finish.
    pub(crate) fn keep(&self, t: usize, current: impl Fn(usize) -> f64, m: &mut Memory<'_>) {
        let now = t % m.ring_len(self);
        for s in 0..self.signals {
            m.keep(self, s, t, now, current(s));
        }
    }

    /// Add sample t's products with itself and the L samples before it,
    /// `past(z, d)` being signal z at sample `t - d` with its halves.
    fn gain(
        &self,
        t: usize,
        current: &impl Fn(usize) -> f64,
        past: impl Fn(usize, usize) -> (f64, (f64, f64)),
        normalize: bool,
        sums: &mut [f64],
    ) {
        for x in 0..self.signals {
            let cx = current(x);
            let sx = split(cx);
            for z in (0..self.signals).filter(|z| self.needed(x, *z)) {
                for d in 0..=self.lags.min(t) {
                    let (zv, sz) = if d == 0 {
                        let cz = current(z);
                        (cz, split(cz))
                    } else {
                        past(z, d)
                    };
                    let k = self.slot(x, z, d);
                    let sum = dd::accumulate(load(sums, k), cx, sx, sz, zv);
                    store(sums, k, if normalize { sum.normalized() } else { sum });
                }
            }
        }
    }

    /// Subtract every product of sample `o`, the oldest of a full window,
    /// with the samples after it: `x(o + d) z(o)` for each lag difference.
    fn forget(&self, o: usize, m: &mut Memory<'_>) {
        let ring = m.ring_len(self);
        let oldest = o % ring;
        let ahead = |d: usize| {
            let slot = oldest + d;
            if slot >= ring { slot - ring } else { slot }
        };
        for z in 0..self.signals {
            let (zv, sz) = m.at_slot(self, z, oldest);
            for x in (0..self.signals).filter(|x| self.needed(*x, z)) {
                for d in 0..=self.lags {
                    let (xv, (hi, lo)) = m.at_slot(self, x, ahead(d));
                    let k = self.slot(x, z, d);
                    let sum = dd::accumulate(load(m.sums, k), -xv, (-hi, -lo), sz, zv);
                    store(m.sums, k, sum.normalized());
                }
            }
        }
    }

    /// `sum_{t = L}^{n-1} x(t - la) z(t - lb)` over the last `n > L` of
    /// `pushed` samples (all of them for a record, the window's for a
    /// window).
    pub(crate) fn entry(
        &self,
        m: &Memory<'_>,
        n: usize,
        pushed: usize,
        a: (usize, usize),
        b: (usize, usize),
    ) -> Dd {
        let ((x, la), (z, lb)) = if a.1 <= b.1 { (a, b) } else { (b, a) };
        let d = lb - la;
        let mut sum = load(m.sums, self.slot(x, z, d)).normalized();
        // The full correlation runs over tau = 0..n-d; the regression over
        // tau = L-lb..n-lb.
        let ends = (0..self.lags - lb).chain(n - lb..n - d);
        for tau in ends {
            let p = two_prod(
                m.value(self, x, tau + d, n, pushed),
                m.value(self, z, tau, n, pushed),
            );
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

/// Packed lower-triangle index of (row, column), column <= row.
#[inline]
pub(crate) fn packed(row: usize, column: usize) -> usize {
    row * (row + 1) / 2 + column
}

/// Solve the packed normal equations in `sums` (overwritten) into `alpha`, in
/// double-double, with the QR rank test's tolerance on each pivot's sine.
/// `Err(Some(column))` for a rank deficiency, `Err(None)` for overflow.
pub(crate) fn solve(sums: &mut [f64], n: usize, alpha: &mut [f64]) -> Result<(), Option<usize>> {
    let tolerance = Dd::from_f64(RANK_TOLERANCE * RANK_TOLERANCE);
    for j in 0..n {
        let diagonal = load(sums, packed(j, j));
        if !(diagonal.hi.is_finite() && diagonal.lo.is_finite()) {
            return Err(None);
        }
        let mut pivot = diagonal;
        for k in 0..j {
            let l = load(sums, packed(j, k));
            pivot = pivot.sub(l.mul(l));
        }
        // The squared sine of column j's angle to the ones before it.
        if !(diagonal.hi > 0.0 && pivot.hi > tolerance.mul(diagonal).hi) {
            return Err(Some(j));
        }
        let root = pivot.sqrt();
        store(sums, packed(j, j), root);
        for i in j + 1..n {
            let mut s = load(sums, packed(i, j));
            for k in 0..j {
                s = s.sub(load(sums, packed(i, k)).mul(load(sums, packed(j, k))));
            }
            store(sums, packed(i, j), s.div(root));
        }
    }
    let rhs = packed(n, 0);
    // L z = b, then L' x = z, in place in the right-hand side.
    for i in 0..n {
        let mut s = load(sums, rhs + i);
        for k in 0..i {
            s = s.sub(load(sums, packed(i, k)).mul(load(sums, rhs + k)));
        }
        store(sums, rhs + i, s.div(load(sums, packed(i, i))));
    }
    for i in (0..n).rev() {
        let mut s = load(sums, rhs + i);
        for k in i + 1..n {
            s = s.sub(load(sums, packed(k, i)).mul(load(sums, rhs + k)));
        }
        store(sums, rhs + i, s.div(load(sums, packed(i, i))));
    }
    for (i, a) in alpha.iter_mut().enumerate().take(n) {
        *a = load(sums, rhs + i).to_f64();
        if !a.is_finite() {
            return Err(None);
        }
    }
    Ok(())
}
