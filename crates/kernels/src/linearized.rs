//! A stage 1 that linearizes the model at one parameter vector, the
//! anchor: the record's residual against the model's response at the
//! anchor is regressed by least squares on the model's output
//! sensitivities there. That is eq. (2) of the paper with the model's own
//! regressors instead of lagged signals, and one Gauss-Newton step from
//! the anchor: its coefficients are what the record says of the
//! parameters, its Gram how much it says, whatever the input that drove
//! it. The model runs at the anchor alone, on the record's input, once,
//! sample by sample, so a control unit streams it as it streams ARX sums.
//!
//! The features, for `q = 2` parameters of widths `w` in the box
//! `[lower, upper]`: the step's end clipped to the box (2), the step in
//! widths (2), each parameter's standard deviation under the
//! linearization in widths, as a logarithm (2), their correlation (1),
//! and the logarithm of the residual's mean square at the anchor in the
//! noise's variances (1).

use crate::pacejka::{Car, Dual2, Real};

/// Features of a linearized stage 1 of two parameters.
pub const LINEARIZED_FEATURES: usize = 8;

/// The most Runge-Kutta steps per sample (the cost grows with them).
pub const MAX_SUBSTEPS: u32 = 20;

/// The sums a record's samples add up to: the sensitivities' Gram
/// `(s1 s1, s1 s2, s2 s2)`, their products with the residual, the
/// residual's squares and the count of samples.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinearizedSums {
    /// `sum s1^2`, `sum s1 s2`, `sum s2^2`.
    pub gram: [f64; 3],
    /// `sum s1 r`, `sum s2 r`.
    pub cross: [f64; 2],
    /// `sum r^2`.
    pub residual_squares: f64,
    /// Samples added.
    pub count: usize,
}

impl LinearizedSums {
    /// How many numbers [`Self::to_words`] writes.
    pub const WORDS: usize = 7;

    /// The sums as numbers: the Gram, the cross products, the residual's
    /// squares, the count.
    pub fn to_words(&self) -> [f64; Self::WORDS] {
        let [g0, g1, g2] = self.gram;
        let [c0, c1] = self.cross;
        [g0, g1, g2, c0, c1, self.residual_squares, self.count as f64]
    }

    /// The sums [`Self::to_words`] wrote.
    pub fn from_words(w: &[f64; Self::WORDS]) -> Self {
        Self {
            gram: [w[0], w[1], w[2]],
            cross: [w[3], w[4]],
            residual_squares: w[5],
            count: w[6] as usize,
        }
    }

    /// Add another run of samples' sums to these (a window's blocks).
    pub fn merge(&mut self, other: &Self) {
        for (a, b) in self.gram.iter_mut().zip(&other.gram) {
            *a += b;
        }
        for (a, b) in self.cross.iter_mut().zip(&other.cross) {
            *a += b;
        }
        self.residual_squares += other.residual_squares;
        self.count += other.count;
    }

    /// Add one sample's sensitivities `s` and residual `r`.
    #[inline]
    pub fn add(&mut self, s: [f64; 2], r: f64) {
        self.gram[0] += s[0] * s[0];
        self.gram[1] += s[0] * s[1];
        self.gram[2] += s[1] * s[1];
        self.cross[0] += s[0] * r;
        self.cross[1] += s[1] * r;
        self.residual_squares += r * r;
        self.count += 1;
    }
}

/// How a window of a linearized stage 1 counts its samples: in blocks of
/// `len` samples from the stream's first, of which `count` fit in the
/// window. Its sums cannot lose a sample (the car's sensitivities of a
/// sample are not kept), so the window gains whole blocks and loses whole
/// blocks: at a finish it holds the current block's samples and the whole
/// blocks before it that fit in its length.
///
/// ```
/// use twostage_kernels::linearized::WindowBlocks;
/// let blocks = WindowBlocks::of(500);
/// assert_eq!((blocks.len, blocks.count), (50, 10));
/// // At a block's end the whole window; inside one, its samples so far
/// // and the nine whole blocks before it.
/// assert_eq!(blocks.summed(1200), 14..24);
/// assert_eq!(blocks.summed(1210), 15..24);
/// assert_eq!(blocks.first_sample(1210), 750);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WindowBlocks {
    /// Samples a block.
    pub len: usize,
    /// Whole blocks that fit in the window.
    pub count: usize,
}

/// Blocks a linearized window is counted in: a tenth of the window each,
/// so that it spans its length to within a tenth.
pub const WINDOW_BLOCKS: usize = 10;

impl WindowBlocks {
    /// The blocks of a window of `window` samples (none for a record).
    pub fn of(window: usize) -> Self {
        if window == 0 {
            return Self { len: 0, count: 0 };
        }
        let len = window.div_ceil(WINDOW_BLOCKS);
        Self {
            len,
            count: window / len,
        }
    }

    /// The whole blocks a finish after `pushed` samples sums, oldest
    /// first (absolute block numbers), besides the current block's
    /// samples.
    pub fn summed(&self, pushed: usize) -> core::ops::Range<usize> {
        let completed = pushed / self.len.max(1);
        let partial = !pushed.is_multiple_of(self.len.max(1));
        let whole = self
            .count
            .saturating_sub(usize::from(partial))
            .min(completed);
        completed - whole..completed
    }

    /// The first sample a finish after `pushed` samples sums.
    pub fn first_sample(&self, pushed: usize) -> usize {
        self.summed(pushed).start * self.len
    }
}

/// How the car is linearized: its constants, the anchor, the noise
/// variance the Gram is scaled by, the prior's box and the Runge-Kutta
/// steps per sample.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CarLinearization {
    /// The car's constants.
    pub car: Car,
    /// The parameters the car is linearized at (the box's centre).
    pub anchor: [f64; 2],
    /// The box the step's end is clipped to, and whose widths scale it.
    pub lower: [f64; 2],
    /// The box's upper corner.
    pub upper: [f64; 2],
    /// The output noise's variance (the Gram's unit).
    pub noise_variance: f64,
    /// The sample period, s.
    pub sample_time: f64,
    /// Runge-Kutta steps per sample.
    pub substeps: u32,
}

/// The car at the anchor, run on a record's input sample by sample, with
/// the output's derivatives: what a record's sums need, and nothing of the
/// record kept.
#[derive(Debug, Clone, Copy)]
pub struct CarStream {
    state: [Dual2; 4],
    last_input: f64,
    started: bool,
    /// The sums so far.
    pub sums: LinearizedSums,
}

impl Default for CarStream {
    fn default() -> Self {
        Self::new()
    }
}

impl CarStream {
    /// How many numbers [`Self::to_words`] writes: the state's values and
    /// derivatives, the last input, whether a sample was seen, the sums.
    pub const WORDS: usize = 14 + LinearizedSums::WORDS;

    /// The stream as numbers, to keep in a workspace between samples.
    pub fn to_words(&self) -> [f64; Self::WORDS] {
        let mut w = [0.0; Self::WORDS];
        for (i, x) in self.state.iter().enumerate() {
            w[3 * i] = x.value;
            w[3 * i + 1] = x.grad[0];
            w[3 * i + 2] = x.grad[1];
        }
        w[12] = self.last_input;
        w[13] = if self.started { 1.0 } else { 0.0 };
        w[14..].copy_from_slice(&self.sums.to_words());
        w
    }

    /// The stream [`Self::to_words`] wrote (all zeros: a new stream).
    pub fn from_words(w: &[f64; Self::WORDS]) -> Self {
        let mut sums = [0.0; LinearizedSums::WORDS];
        sums.copy_from_slice(&w[14..]);
        Self {
            state: core::array::from_fn(|i| Dual2 {
                value: w[3 * i],
                grad: [w[3 * i + 1], w[3 * i + 2]],
            }),
            last_input: w[12],
            started: w[13] != 0.0,
            sums: LinearizedSums::from_words(&sums),
        }
    }

    /// At rest, no sample seen (the car's records start from rest).
    pub fn new() -> Self {
        Self {
            state: [Dual2::default(); 4],
            last_input: 0.0,
            started: false,
            sums: LinearizedSums::default(),
        }
    }

    /// Take sample `(u, y)`: move the model from the last sample's time to
    /// this one (the input linear between them), then add the sensitivities
    /// and residual of its output here. Returns them.
    pub fn push(&mut self, lin: &CarLinearization, u: f64, y: f64) -> ([f64; 2], f64) {
        let theta = [
            Dual2::variable(lin.anchor[0], 0),
            Dual2::variable(lin.anchor[1], 1),
        ];
        if self.started {
            let steps = lin.substeps.max(1);
            let h = lin.sample_time / f64::from(steps);
            let (from, to) = (self.last_input, u);
            for j in 0..steps {
                let steer = |tau: f64| {
                    let at = (f64::from(j) + tau) / f64::from(steps);
                    from + at * (to - from)
                };
                lin.car.rk4_step(theta, h, steer, &mut self.state);
            }
        }
        self.started = true;
        self.last_input = u;
        let out = lin
            .car
            .lateral_acceleration(theta, Dual2::constant(u), &self.state);
        let r = y - out.value();
        self.sums.add(out.grad, r);
        (out.grad, r)
    }
}

impl CarLinearization {
    /// How many numbers [`Self::to_words`] writes: the car's, the anchor,
    /// the box's lower and upper corners, the noise variance, the sample
    /// time and the steps a sample.
    pub const WORDS: usize = Car::WORDS + 9;

    /// The linearization as numbers: how the runtime's blob stores it.
    ///
    /// ```
    /// use twostage_kernels::linearized::CarLinearization;
    /// use twostage_kernels::pacejka::Car;
    /// let lin = CarLinearization {
    ///     car: Car::PAPER, anchor: [-35.0, -1.1], lower: [-42.0, -1.2], upper: [-28.0, -1.0],
    ///     noise_variance: 0.01, sample_time: 0.02, substeps: 2,
    /// };
    /// assert_eq!(lin.fault(), None);
    /// assert_eq!(CarLinearization::from_words(&lin.to_words()), Ok(lin));
    /// let mut damaged = lin.to_words();
    /// damaged[CarLinearization::WORDS - 1] = 0.0; // no step a sample
    /// assert!(CarLinearization::from_words(&damaged).is_err());
    /// ```
    pub fn to_words(&self) -> [f64; Self::WORDS] {
        let mut w = [0.0; Self::WORDS];
        w[..Car::WORDS].copy_from_slice(&self.car.to_words());
        let rest = [
            self.anchor[0],
            self.anchor[1],
            self.lower[0],
            self.lower[1],
            self.upper[0],
            self.upper[1],
            self.noise_variance,
            self.sample_time,
            f64::from(self.substeps),
        ];
        w[Car::WORDS..].copy_from_slice(&rest);
        w
    }

    /// The linearization [`Self::to_words`] wrote, checked as
    /// [`Self::fault`] checks it; `Err` says what is wrong.
    ///
    /// # Errors
    /// A slice of another length, and every fault of [`Self::fault`].
    pub fn from_words(w: &[f64]) -> Result<Self, &'static str> {
        let Some((car, rest)) = w.split_first_chunk::<{ Car::WORDS }>() else {
            return Err("the linearization's numbers are too few");
        };
        let &[
            a0,
            a1,
            l0,
            l1,
            u0,
            u1,
            noise_variance,
            sample_time,
            substeps,
        ] = rest
        else {
            return Err("the linearization's numbers are too few or too many");
        };
        let whole = (1.0..=f64::from(MAX_SUBSTEPS)).contains(&substeps)
            && libm::trunc(substeps).to_bits() == substeps.to_bits();
        if !whole {
            return Err("the Runge-Kutta steps a sample must be a whole number from 1 to 20");
        }
        let lin = Self {
            car: Car::from_words(car),
            anchor: [a0, a1],
            lower: [l0, l1],
            upper: [u0, u1],
            noise_variance,
            sample_time,
            substeps: substeps as u32,
        };
        lin.fault().map_or(Ok(lin), Err)
    }

    /// What is wrong with the linearization, `None` when nothing is: every
    /// number finite, the box of positive width with the anchor at its
    /// centre, a positive noise variance and sample time, 1 to
    /// [`MAX_SUBSTEPS`] steps a sample.
    pub fn fault(&self) -> Option<&'static str> {
        let numbers = self.to_words();
        if !numbers.iter().all(|x| x.is_finite()) {
            return Some("every number of the linearization must be finite");
        }
        for j in 0..2 {
            if self.upper[j] <= self.lower[j] {
                return Some("the prior box must have a positive width");
            }
            if (self.anchor[j] - 0.5 * (self.lower[j] + self.upper[j])).abs() > 0.0 {
                return Some("the anchor must be the prior box's centre");
            }
        }
        if self.noise_variance <= 0.0 {
            return Some("the noise variance must be positive");
        }
        if self.sample_time <= 0.0 {
            return Some("the sample time must be positive");
        }
        if !(1..=MAX_SUBSTEPS).contains(&self.substeps) {
            return Some("the Runge-Kutta steps a sample must be a whole number from 1 to 20");
        }
        None
    }

    /// The features of a record's `sums` into `out` (at least
    /// [`LINEARIZED_FEATURES`] long), or `None` when the sums are not
    /// finite (the model left its range on the record's input: the
    /// caller says so with the record).
    ///
    /// ```
    /// use twostage_kernels::linearized::{CarLinearization, LinearizedSums};
    /// use twostage_kernels::pacejka::Car;
    /// let lin = CarLinearization {
    ///     car: Car::PAPER, anchor: [-35.0, -1.1], lower: [-42.0, -1.2], upper: [-28.0, -1.0],
    ///     noise_variance: 0.01, sample_time: 0.02, substeps: 1,
    /// };
    /// // A residual that is 0.5 times the first sensitivity: a step of 0.5
    /// // in pK1 (a little less: the weak prior of half the box pulls).
    /// let mut sums = LinearizedSums::default();
    /// for k in 0..500 {
    ///     let s = [(k as f64 * 0.1).sin(), 0.01 * (k as f64 * 0.05).cos()];
    ///     sums.add(s, 0.5 * s[0]);
    /// }
    /// let mut f = [0.0; 8];
    /// lin.features(&sums, &mut f).unwrap();
    /// assert!((f[0] - (-34.5)).abs() < 1e-3 && f[0] < -34.5, "{f:?}");
    /// ```
    pub fn features(&self, sums: &LinearizedSums, out: &mut [f64]) -> Option<()> {
        let out = out.get_mut(..LINEARIZED_FEATURES)?;
        let width = [self.upper[0] - self.lower[0], self.upper[1] - self.lower[1]];
        // Normal equations in the noise's units with a weak prior (each
        // parameter's standard deviation half its box), so that a record
        // that says nothing of a parameter leaves it at the anchor.
        let v = self.noise_variance;
        let a = sums.gram[0] / v + 4.0 / (width[0] * width[0]);
        let b = sums.gram[1] / v;
        let d = sums.gram[2] / v + 4.0 / (width[1] * width[1]);
        let (g0, g1) = (sums.cross[0] / v, sums.cross[1] / v);
        let det = a * d - b * b;
        let finite = [a, b, d, g0, g1, sums.residual_squares]
            .iter()
            .all(|x| x.is_finite());
        if !finite || det <= 0.0 {
            return None;
        }
        let step = [(d * g0 - b * g1) / det, (a * g1 - b * g0) / det];
        let variance = [d / det, a / det];
        let sd = [crate::sqrt(variance[0]), crate::sqrt(variance[1])];
        // The box's own clip (f64::clamp would bring float formatting into
        // a firmware with its panic).
        let mut end = [self.anchor[0] + step[0], self.anchor[1] + step[1]];
        crate::vector::clip_to_box(&mut end, &self.lower[..], &self.upper[..]);
        for j in 0..2 {
            out[j] = end[j];
            out[2 + j] = step[j] / width[j];
            out[4 + j] = libm::log(sd[j] / width[j]);
        }
        out[6] = -b / det / (sd[0] * sd[1]);
        // In the noise's units, floored so that a record the anchor fits
        // exactly (a car at rest) stays a number stage 2 can scale.
        let mean_square = sums.residual_squares / sums.count.max(1) as f64 / v;
        out[7] = libm::log(mean_square.max(1e-6));
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lin() -> CarLinearization {
        CarLinearization {
            car: Car::PAPER,
            anchor: [-35.0, -1.1],
            lower: [-42.0, -1.2],
            upper: [-28.0, -1.0],
            noise_variance: 0.01,
            sample_time: 0.02,
            substeps: 2,
        }
    }

    /// The fault's words name the limit the code holds.
    #[test]
    fn the_steps_fault_names_the_limit() {
        let mut many = lin();
        many.substeps = MAX_SUBSTEPS + 1;
        let why = many.fault().unwrap();
        assert!(
            why.ends_with(&std::format!("from 1 to {MAX_SUBSTEPS}")),
            "{why}"
        );
        let mut words = lin().to_words();
        words[CarLinearization::WORDS - 1] = 2.5;
        assert_eq!(CarLinearization::from_words(&words), Err(why));
    }

    /// Each fault is found: a box inverted, the anchor off centre, a
    /// noise of no variance, a NaN constant, a slice too short.
    #[test]
    fn every_fault_is_found() {
        let mut inverted = lin();
        inverted.lower[1] = -0.9;
        let mut off = lin();
        off.anchor[0] = -34.0;
        let mut silent = lin();
        silent.noise_variance = 0.0;
        let mut nan = lin();
        nan.car.vehicle.speed = f64::NAN;
        for (bad, says) in [
            (inverted, "width"),
            (off, "centre"),
            (silent, "noise"),
            (nan, "finite"),
        ] {
            assert!(bad.fault().unwrap().contains(says), "{:?}", bad.fault());
            assert!(CarLinearization::from_words(&bad.to_words()).is_err());
        }
        assert!(CarLinearization::from_words(&lin().to_words()[1..]).is_err());
    }

    /// A stream kept as numbers and read back goes on as the stream
    /// itself, to the bit; block sums merged are the sums of the whole.
    #[test]
    fn a_stream_kept_in_words_goes_on_as_itself() {
        let lin = lin();
        let (mut kept, mut alone) = (CarStream::new().to_words(), CarStream::new());
        let (mut blocks, mut block) = (LinearizedSums::default(), LinearizedSums::default());
        for k in 0..200 {
            let (u, y) = (0.05 * (0.1 * k as f64).sin(), 0.3 * (0.1 * k as f64).cos());
            let mut resumed = CarStream::from_words(&kept);
            let (s, r) = resumed.push(&lin, u, y);
            kept = resumed.to_words();
            alone.push(&lin, u, y);
            block.add(s, r);
            if k % 30 == 29 {
                blocks.merge(&block);
                block = LinearizedSums::default();
            }
        }
        blocks.merge(&block);
        assert_eq!(kept.map(f64::to_bits), alone.to_words().map(f64::to_bits));
        assert_eq!(blocks.count, alone.sums.count);
        for (a, b) in blocks.to_words().iter().zip(alone.sums.to_words()) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} {b}");
        }
    }
}
