//! An input between its samples, for models integrated in continuous
//! time: the chicane exactly, a sampled signal interpolated.

use std::f64::consts::PI;

use super::{InputSignal, Kind};

impl InputSignal {
    /// The input at continuous time `t`, for models integrated between
    /// samples. The chicane is evaluated exactly; sampled signals (noise
    /// realizations and fixed signals, passed as `samples` = the output of
    /// [`InputSignal::fill`]) are interpolated linearly between samples and
    /// held after the last one (docs/decisions/005-continuous-time-inputs.md).
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
    /// linear between samples, held after the last, as
    /// [`InputSignal::value_at`] takes sampled designs.
    ///
    /// ```
    /// use twostage_models::InputSignal;
    /// assert_eq!(InputSignal::sampled_value_at(0.75, 0.5, &[0.0, 1.0, 3.0]), 2.0);
    /// assert_eq!(InputSignal::sampled_value_at(9.0, 0.5, &[0.0, 1.0, 3.0]), 3.0);
    /// ```
    pub fn sampled_value_at(t: f64, sample_time: f64, samples: &[f64]) -> f64 {
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
