//! Digital Butterworth filters by the bilinear transform with the band
//! edges prewarped, as cascades of second-order sections: the filters
//! that shape band-limited Gaussian noise inputs.
//!
//! A low-pass of order `n` and edge `f` (sample time `T`) has the power
//! response `1 / (1 + (tan(w / 2) / tan(pi f T))^(2 n))` at the digital
//! frequency `w` in radians per sample; a high-pass the same with the
//! ratio inverted. Those closed forms are what the tests hold the
//! sections to.

use crate::InvalidSetting;
use std::f64::consts::PI;

use crate::error::{Result, SimError};

/// The highest filter order a design takes: a higher order sharpens the
/// band's edges little more and lengthens the start-up a record discards.
pub const MAX_FILTER_ORDER: u32 = 10;

/// One second-order section `(b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2
/// z^-2)` (a first-order section has `b2 = a2 = 0`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Section {
    pub(crate) b: [f64; 3],
    pub(crate) a: [f64; 2],
}

/// A cascade of sections and its state (transposed direct form II).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cascade {
    sections: Vec<Section>,
    state: Vec<[f64; 2]>,
}

/// Which side of its edge a filter passes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Pass {
    Low,
    High,
}

impl Cascade {
    /// An empty cascade: it passes its input unchanged.
    pub(crate) fn new() -> Self {
        Self {
            sections: Vec::new(),
            state: Vec::new(),
        }
    }

    /// Append a Butterworth filter of `order` passing `pass` of `edge` Hz
    /// at `sample_time` s.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for an order outside 1 to
    /// [`MAX_FILTER_ORDER`], or an edge not strictly between 0 and the
    /// Nyquist frequency.
    pub(crate) fn butterworth(
        mut self,
        pass: Pass,
        order: u32,
        edge: f64,
        sample_time: f64,
    ) -> Result<Self> {
        if !(1..=MAX_FILTER_ORDER).contains(&order) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "filter order",
                value: order.to_string(),
                reason: format!("give an order of 1 to {MAX_FILTER_ORDER}"),
            }));
        }
        let nyquist = 0.5 / sample_time;
        if !(edge > 0.0 && edge < nyquist) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "filter edge",
                value: format!("{edge} Hz"),
                reason: format!(
                    "give an edge above 0 and below the Nyquist frequency {nyquist} Hz"
                ),
            }));
        }
        // The analog edge prewarped so that the digital edge lands on
        // `edge`: s = (1 - z^-1) / (K (1 + z^-1)) for a low-pass, its
        // reciprocal for a high-pass, with K = tan(pi f T).
        let k = (PI * edge * sample_time).tan();
        let numerator = |pass: Pass| match pass {
            Pass::Low => [1.0, 2.0, 1.0],
            Pass::High => [1.0, -2.0, 1.0],
        };
        for i in 0..order / 2 {
            // The pole pair at angle phi from the imaginary axis:
            // s^2 + 2 sin(phi) s + 1.
            let phi = PI * f64::from(2 * i + 1) / f64::from(2 * order);
            let damping = 2.0 * phi.sin() * k;
            let a0 = 1.0 + damping + k * k;
            let gain = match pass {
                Pass::Low => k * k / a0,
                Pass::High => 1.0 / a0,
            };
            let b = numerator(pass).map(|c| c * gain);
            self.sections.push(Section {
                b,
                a: [2.0 * (k * k - 1.0) / a0, (1.0 - damping + k * k) / a0],
            });
        }
        if order % 2 == 1 {
            // The real pole: s + 1.
            let a0 = 1.0 + k;
            let b = match pass {
                Pass::Low => [k / a0, k / a0, 0.0],
                Pass::High => [1.0 / a0, -1.0 / a0, 0.0],
            };
            self.sections.push(Section {
                b,
                a: [(k - 1.0) / a0, 0.0],
            });
        }
        self.state = vec![[0.0; 2]; self.sections.len()];
        Ok(self)
    }

    /// The sections, first to last.
    #[cfg(test)]
    pub(crate) fn sections(&self) -> &[Section] {
        &self.sections
    }

    /// Filter one sample.
    pub(crate) fn step(&mut self, x: f64) -> f64 {
        let mut v = x;
        for (s, z) in self.sections.iter().zip(&mut self.state) {
            let y = s.b[0] * v + z[0];
            z[0] = s.b[1] * v - s.a[0] * y + z[1];
            z[1] = s.b[2] * v - s.a[1] * y;
            v = y;
        }
        v
    }

    /// Back to rest.
    pub(crate) fn reset(&mut self) {
        self.state.iter_mut().for_each(|z| *z = [0.0; 2]);
    }

    /// The energy of the impulse response (the output variance for a
    /// white input of unit variance) and the samples after which what is
    /// left of it falls below `1e-15` of it: a start-up that long leaves
    /// the filtered noise stationary to that precision. `None` when the
    /// response has not died away within `limit` samples.
    pub(crate) fn energy_and_settling(&mut self, limit: usize) -> Option<(f64, usize)> {
        self.reset();
        let (mut energy, mut block) = (0.0, 0.0);
        const BLOCK: usize = 64;
        for k in 0..limit {
            let h = self.step(if k == 0 { 1.0 } else { 0.0 });
            energy += h * h;
            block += h * h;
            if (k + 1) % BLOCK == 0 {
                // A block that adds nothing to the energy after the
                // response has risen: the rest decays geometrically.
                if k + 1 >= 4 * BLOCK && block <= 1e-17 * energy {
                    self.reset();
                    return Some((energy, k + 1));
                }
                block = 0.0;
            }
        }
        self.reset();
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The power response of the cascade at `w` radians per sample,
    /// evaluated from its coefficients in complex arithmetic.
    fn power(cascade: &Cascade, w: f64) -> f64 {
        let (c1, s1, c2, s2) = (w.cos(), -w.sin(), (2.0 * w).cos(), -(2.0 * w).sin());
        cascade.sections().iter().fold(1.0, |p, s| {
            let (nr, ni) = (
                s.b[0] + s.b[1] * c1 + s.b[2] * c2,
                s.b[1] * s1 + s.b[2] * s2,
            );
            let (dr, di) = (1.0 + s.a[0] * c1 + s.a[1] * c2, s.a[0] * s1 + s.a[1] * s2);
            p * (nr * nr + ni * ni) / (dr * dr + di * di)
        })
    }

    #[test]
    fn sections_have_the_closed_form_power_response() {
        let dt = 0.01;
        for order in 1..=MAX_FILTER_ORDER {
            for edge in [0.3, 5.0, 20.0, 49.0] {
                let k = (PI * edge * dt).tan();
                let low = Cascade::new()
                    .butterworth(Pass::Low, order, edge, dt)
                    .unwrap();
                let high = Cascade::new()
                    .butterworth(Pass::High, order, edge, dt)
                    .unwrap();
                for i in 1..200 {
                    let w = PI * f64::from(i) / 200.0;
                    let ratio = (w / 2.0).tan() / k;
                    let want_low = 1.0 / (1.0 + ratio.powi(2 * order as i32));
                    let want_high = 1.0 / (1.0 + ratio.powi(-2 * order as i32));
                    for (got, want) in [(power(&low, w), want_low), (power(&high, w), want_high)] {
                        assert!(
                            (got - want).abs() <= 1e-9 * want.max(1e-12) + 1e-14,
                            "order {order}, edge {edge}, w {w}: {got} against {want}"
                        );
                    }
                }
                // Half power at the edge itself.
                let w_edge = 2.0 * PI * edge * dt;
                assert!((power(&low, w_edge) - 0.5).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn the_impulse_energy_is_the_integral_of_the_power_response() {
        for (pass, order, edge) in [
            (Pass::Low, 4, 5.0),
            (Pass::High, 3, 2.0),
            (Pass::Low, 10, 0.5),
        ] {
            let mut filter = Cascade::new().butterworth(pass, order, edge, 0.01).unwrap();
            let (energy, settled) = filter.energy_and_settling(1_000_000).unwrap();
            // Parseval: the energy is (1 / pi) times the integral of the
            // power response over [0, pi] (Simpson's rule, fine grid).
            let m = 200_000;
            let h = PI / f64::from(m);
            let mut integral = power(&filter, 0.0) + power(&filter, PI);
            for i in 1..m {
                let weight = if i % 2 == 1 { 4.0 } else { 2.0 };
                integral += weight * power(&filter, h * f64::from(i));
            }
            let parseval = integral * h / 3.0 / PI;
            assert!(
                (energy - parseval).abs() < 1e-6 * parseval,
                "{pass:?} {order} at {edge} Hz: {energy} against {parseval}"
            );
            assert!(settled > 0 && settled < 1_000_000);
        }
        let mut narrow = Cascade::new()
            .butterworth(Pass::Low, 8, 0.001, 0.01)
            .unwrap();
        assert!(narrow.energy_and_settling(10_000).is_none());
    }

    #[test]
    fn impossible_filters_are_refused() {
        for (order, edge) in [(0, 1.0), (11, 1.0), (2, 0.0), (2, 50.0), (2, f64::NAN)] {
            assert!(
                Cascade::new()
                    .butterworth(Pass::Low, order, edge, 0.01)
                    .is_err(),
                "order {order} edge {edge}"
            );
        }
    }
}
