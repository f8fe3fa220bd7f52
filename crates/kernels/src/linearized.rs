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
        for j in 0..2 {
            out[j] = (self.anchor[j] + step[j]).clamp(self.lower[j], self.upper[j]);
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
