//! An input between its samples, for models integrated in continuous
//! time: the chicane exactly, a sampled signal by the cubic through its
//! four nearest samples where it is smooth, kept straight where it holds.

use std::f64::consts::PI;

use super::{InputSignal, Kind};

impl InputSignal {
    /// The input at continuous time `t`, for models integrated between
    /// samples. The chicane is evaluated exactly; sampled signals (noise
    /// realizations and fixed signals, passed as `samples` = the output of
    /// [`InputSignal::fill`]) are read as [`InputSignal::sampled_value_at`]
    /// reads them.
    pub fn value_at(&self, t: f64, sample_time: f64, samples: &[f64]) -> f64 {
        match &self.kind {
            Kind::Chicane { amplitude } => chicane(*amplitude, t),
            Kind::WhiteGaussian { .. }
            | Kind::Fixed(_)
            | Kind::Designed { .. }
            | Kind::Sum(_)
            | Kind::OneOf { .. }
            | Kind::Sequence(_) => Self::sampled_value_at(t, sample_time, samples),
        }
    }

    /// A sampled signal (a measured input, say) at continuous time `t`:
    /// between two samples, the cubic through them and their outer
    /// neighbours (the signal's shape, not the chord a linear reading
    /// cuts: a 0.6 Hz sine sampled at 50 Hz is read within 1e-6 of its
    /// amplitude instead of 7e-4); straight where no neighbour lies on
    /// either side (the first and last intervals) or where the signal
    /// holds beside the interval (two equal samples: a step of a held
    /// signal is not rung through); the sample itself at every sample
    /// time, held after the last. [`InputSignal::value_at`] takes sampled
    /// designs so.
    ///
    /// ```
    /// use twostage_models::InputSignal;
    /// // A cubic's samples give the cubic back between them.
    /// let cubic = |t: f64| t * t * t - 2.0 * t;
    /// let samples: Vec<f64> = (0..6).map(|k| cubic(k as f64 * 0.5)).collect();
    /// assert!((InputSignal::sampled_value_at(1.2, 0.5, &samples) - cubic(1.2)).abs() < 1e-12);
    /// // A held signal: flat where it holds, straight across its step.
    /// let steps = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    /// assert_eq!(InputSignal::sampled_value_at(0.6, 0.5, &steps), 0.0);
    /// assert_eq!(InputSignal::sampled_value_at(1.25, 0.5, &steps), 0.5);
    /// assert_eq!(InputSignal::sampled_value_at(9.0, 0.5, &steps), 1.0);
    /// ```
    pub fn sampled_value_at(t: f64, sample_time: f64, samples: &[f64]) -> f64 {
        smooth(samples, t / sample_time)
    }

    /// A sampled signal at continuous time `t` read linearly between
    /// samples, held after the last: the straight reading (an equations
    /// model's `inputs = "linear"`), what earlier versions read.
    ///
    /// ```
    /// use twostage_models::InputSignal;
    /// assert_eq!(InputSignal::linear_value_at(0.75, 0.5, &[0.0, 1.0, 3.0]), 2.0);
    /// assert_eq!(InputSignal::linear_value_at(9.0, 0.5, &[0.0, 1.0, 3.0]), 3.0);
    /// ```
    pub fn linear_value_at(t: f64, sample_time: f64, samples: &[f64]) -> f64 {
        interpolate(samples, t / sample_time)
    }
}

pub(super) fn chicane(amplitude: f64, t: f64) -> f64 {
    if (1.0..=9.0).contains(&t) {
        let s = (PI * (t - 1.0) / 8.0).sin();
        amplitude * (2.0 * PI * (t - 1.0) / 4.0).sin() * s * s
    } else {
        0.0
    }
}

/// `samples` at fractional index `x` by the cubic through the four
/// samples around it where the signal is smooth there, else linearly
/// ([`InputSignal::sampled_value_at`]).
pub(super) fn smooth(samples: &[f64], x: f64) -> f64 {
    let n = samples.len();
    if !(x > 1.0 && x < n as f64 - 2.0) {
        return interpolate(samples, x);
    }
    let k = x.floor();
    let i = k as usize;
    let (before, a, b, after) = (samples[i - 1], samples[i], samples[i + 1], samples[i + 2]);
    if holds(before, a) || holds(a, b) || holds(b, after) {
        return interpolate(samples, x);
    }
    // Lagrange's weights of the nodes -1, 0, 1, 2 at s in [0, 1).
    let s = x - k;
    let (sm, s1, s2) = (s + 1.0, s - 1.0, s - 2.0);
    -s * s1 * s2 / 6.0 * before + sm * s1 * s2 / 2.0 * a - sm * s * s2 / 2.0 * b
        + sm * s * s1 / 6.0 * after
}

/// Whether a signal holds from sample value `a` to `b`: a held signal
/// repeats its value exactly, so no margin.
fn holds(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a == 0.0 && b == 0.0)
}

/// Linear interpolation of `samples` at fractional index `x`.
pub(super) fn interpolate(samples: &[f64], x: f64) -> f64 {
    let Some(&last) = samples.last() else {
        return 0.0;
    };
    if x <= 0.0 {
        return samples[0];
    }
    if x.is_nan() {
        return f64::NAN;
    }
    // At or past the last sample (an infinite index included) it holds.
    if x >= (samples.len() - 1) as f64 {
        return last;
    }
    let k = x.floor();
    let i = k as usize;
    let frac = x - k;
    samples[i] + frac * (samples[i + 1] - samples[i])
}
