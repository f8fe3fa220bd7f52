//! A design's amplitude spectrum: the relative amplitude of its lines over
//! frequency, given as a table or taken from a measured record, so that a
//! family of inputs can look like the input a plant was measured with.

use std::sync::Arc;

use rustfft::FftPlannerScalar;
use rustfft::num_complex::Complex;

use crate::InvalidSetting;
use crate::error::{Result, SimError};

/// Bands a measured record's spectrum is averaged into at most, over
/// 0 to the Nyquist frequency.
pub const LIKE_BANDS: usize = 256;

/// DFT bins a band of a measured record's spectrum averages at least:
/// one bin's amplitude is as random as the record's phases.
pub const LIKE_BINS_PER_BAND: usize = 4;

/// The unit of a spectrum's frequencies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unit {
    Hz,
    /// Cycles per sample: a measured record's, read at any sample time.
    PerSample,
}

/// Relative amplitudes of a design's lines over frequency: straight lines
/// between a table's points, a measured record's bands each at its own
/// level, the first and last level beyond them.
///
/// ```
/// use twostage_models::Spectrum;
/// // Flat to 150 Hz, then falling to 0.65 at 200 Hz.
/// let s = Spectrum::table(vec![[0.0, 1.0], [150.0, 1.0], [200.0, 0.65]])?;
/// assert_eq!(s.level_at(100.0, 0.001), 1.0);
/// assert!((s.level_at(175.0, 0.001) - 0.825).abs() < 1e-12);
/// assert_eq!(s.level_at(300.0, 0.001), 0.65);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    points: Arc<[[f64; 2]]>,
    unit: Unit,
}

fn invalid(name: &'static str, value: String, reason: &str) -> SimError {
    SimError::InvalidSetting(InvalidSetting {
        name,
        value,
        reason: reason.into(),
    })
}

impl Spectrum {
    /// A table of `[frequency in Hz, relative amplitude]` points, the
    /// frequencies rising.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for no point, a frequency below zero,
    /// not finite or not above the one before, or an amplitude below zero,
    /// not finite, or every one zero.
    pub fn table(points: Vec<[f64; 2]>) -> Result<Self> {
        let shown = || format!("{points:?}");
        if points.is_empty() {
            return Err(invalid(
                "input spectrum",
                shown(),
                "give one or more [frequency in Hz, relative amplitude] points",
            ));
        }
        if let Some(bad) = points
            .iter()
            .find(|[f, a]| !(f.is_finite() && *f >= 0.0 && a.is_finite() && *a >= 0.0))
        {
            return Err(invalid(
                "input spectrum",
                format!("{bad:?}"),
                "each point's frequency and amplitude are finite numbers >= 0",
            ));
        }
        if let Some(pair) = points.windows(2).find(|p| p[1][0] <= p[0][0]) {
            return Err(invalid(
                "input spectrum",
                format!("{:?} then {:?}", pair[0], pair[1]),
                "give the points in rising frequency, each frequency once",
            ));
        }
        if points.iter().all(|[_, a]| *a == 0.0) {
            return Err(invalid(
                "input spectrum",
                shown(),
                "every amplitude is zero: give a relative amplitude above zero somewhere",
            ));
        }
        Ok(Self {
            points: points.into(),
            unit: Unit::Hz,
        })
    }

    /// The shape of a measured record's amplitude spectrum: its mean
    /// removed, the magnitudes of its DFT averaged (root mean square) over
    /// bands of at least [`LIKE_BINS_PER_BAND`] bins, at most
    /// [`LIKE_BANDS`] of them from 0 to the Nyquist frequency, each band a
    /// point at its centre, the largest 1. Its frequencies are the
    /// record's own (cycles per sample), so it reads at the sample time of
    /// the records it shapes.
    ///
    /// ```
    /// use twostage_models::Spectrum;
    /// // Lines on every bin to 200 of 1024 samples: amplitude 1 to bin 100, 0.5 above.
    /// let u: Vec<f64> = (0..1024)
    ///     .map(|t| {
    ///         (1..=200)
    ///             .map(|k| {
    ///                 let a = if k <= 100 { 1.0 } else { 0.5 };
    ///                 let phase = (k * k) as f64;
    ///                 a * (std::f64::consts::TAU * (k * t) as f64 / 1024.0 + phase).cos()
    ///             })
    ///             .sum::<f64>()
    ///     })
    ///     .collect();
    /// let s = Spectrum::like(&u)?;
    /// // Read at a sample time of 0.01 s: bin 50 is 50 / 10.24 Hz.
    /// let level = |bin: f64| s.level_at(bin / 10.24, 0.01);
    /// assert!((level(50.0) - 1.0).abs() < 1e-9 && (level(150.0) - 0.5).abs() < 1e-9);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidData`] for a record too short for two bands
    /// (fewer than `4 LIKE_BINS_PER_BAND + 1` samples), a value not
    /// finite, or one that does not vary.
    pub fn like(samples: &[f64]) -> Result<Self> {
        let n = samples.len();
        let bins = n.saturating_sub(1) / 2;
        if bins < 2 * LIKE_BINS_PER_BAND {
            return Err(SimError::InvalidData(format!(
                "a record of {n} samples is too short to take a spectrum's shape from: give one \
                 of {} samples or more",
                4 * LIKE_BINS_PER_BAND + 1
            )));
        }
        if let Some(k) = samples.iter().position(|v| !v.is_finite()) {
            return Err(SimError::InvalidData(format!(
                "the record to take a spectrum's shape from has a non-finite value at sample {k}"
            )));
        }
        let mean = samples.iter().sum::<f64>() / n as f64;
        let mut spectrum: Vec<Complex<f64>> = samples
            .iter()
            .map(|v| Complex::new(v - mean, 0.0))
            .collect();
        FftPlannerScalar::new()
            .plan_fft_forward(n)
            .process(&mut spectrum);
        let bands = (bins / LIKE_BINS_PER_BAND).min(LIKE_BANDS);
        let mut points = Vec::with_capacity(bands);
        for band in 0..bands {
            // Bins 1..=bins split as evenly as whole bins allow.
            let (first, last) = (1 + band * bins / bands, (band + 1) * bins / bands);
            let power = spectrum[first..=last]
                .iter()
                .map(|c| c.norm_sqr())
                .sum::<f64>()
                / (last + 1 - first) as f64;
            let centre = 0.5 * (first + last) as f64 / n as f64;
            points.push([centre, power.sqrt()]);
        }
        let top = points.iter().fold(0.0f64, |m, [_, a]| m.max(*a));
        if top <= 0.0 {
            return Err(SimError::InvalidData(
                "the record to take a spectrum's shape from does not vary: every sample is its \
                 mean"
                    .into(),
            ));
        }
        for point in &mut points {
            point[1] /= top;
        }
        Ok(Self {
            points: points.into(),
            unit: Unit::PerSample,
        })
    }

    /// The relative amplitude at `frequency` Hz, for records sampled every
    /// `sample_time` s.
    pub fn level_at(&self, frequency: f64, sample_time: f64) -> f64 {
        let x = match self.unit {
            Unit::Hz => frequency,
            Unit::PerSample => frequency * sample_time,
        };
        let points = &self.points;
        let after = points.partition_point(|[f, _]| *f <= x);
        match after {
            0 => points[0][1],
            n if n == points.len() => points[n - 1][1],
            i => {
                let ([f0, a0], [f1, a1]) = (points[i - 1], points[i]);
                match self.unit {
                    Unit::Hz => a0 + (a1 - a0) * (x - f0) / (f1 - f0),
                    // A band's level over its own bins: a line at the edge
                    // of the measured excitation keeps its band's level.
                    Unit::PerSample if x - f0 <= f1 - x => a0,
                    Unit::PerSample => a1,
                }
            }
        }
    }

    /// Its points: `[Hz, level]` for a table, `[cycles per sample,
    /// level]` for a record's shape.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Refuses a table with a point above the Nyquist frequency of
    /// `sample_time` (0: not known yet, nothing refused).
    pub(crate) fn check(&self, sample_time: f64) -> Result<()> {
        let last = self.points[self.points.len() - 1][0];
        if self.unit == Unit::Hz && sample_time > 0.0 && last > 0.5 / sample_time {
            return Err(invalid(
                "input spectrum",
                format!("a point at {last} Hz"),
                &format!(
                    "above the Nyquist frequency {} Hz of the sample time {sample_time} s: no \
                     line of a record lies there; give points up to it",
                    0.5 / sample_time
                ),
            ));
        }
        Ok(())
    }

    pub(crate) fn describe(&self) -> String {
        match self.unit {
            Unit::Hz => format!(
                "line amplitudes shaped by {} point(s) from {} to {} Hz",
                self.points.len(),
                self.points[0][0],
                self.points[self.points.len() - 1][0]
            ),
            Unit::PerSample => format!(
                "line amplitudes shaped like a measured record ({} bands)",
                self.points.len()
            ),
        }
    }
}

/// The lines `k` of the grid `k / (N T)` of a record of `n` samples every
/// `sample_time` s that lie strictly inside (0, Nyquist) and in
/// `[low, top]` Hz: every one, or the odd ones.
pub(crate) fn band_lines(low: f64, top: f64, odd: bool, n: usize, sample_time: f64) -> Vec<usize> {
    let df = 1.0 / (n as f64 * sample_time);
    (1..n.div_ceil(2))
        .filter(|&k| {
            let f = k as f64 * df;
            f >= low && f <= top && (!odd || k % 2 == 1)
        })
        .collect()
}

/// `u[t]` = the real part of the sum over `lines` of
/// `c_k exp(2 pi i k t / N)`: an inverse DFT, in O(N log N).
pub(crate) fn synthesize(lines: &[usize], coefficients: &[Complex<f64>], u: &mut [f64]) {
    let n = u.len();
    let mut spectrum = vec![Complex::new(0.0, 0.0); n];
    for (&k, c) in lines.iter().zip(coefficients) {
        spectrum[k] = *c;
    }
    FftPlannerScalar::new()
        .plan_fft_inverse(n)
        .process(&mut spectrum);
    for (v, c) in u.iter_mut().zip(&spectrum) {
        *v = c.re;
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{filled, line_power};
    use super::super::{Design, Drawn, Grid, Level, Phases};
    use super::*;
    use crate::rng::experiment_rng;

    fn falling() -> Spectrum {
        Spectrum::table(vec![[0.0, 1.0], [10.0, 1.0], [40.0, 0.5]]).unwrap()
    }

    #[test]
    fn a_shaped_multisine_s_lines_follow_the_table() {
        let n = 400; // lines every 0.25 Hz
        let design = Design::Multisine {
            band: (Drawn::fixed(1.0), Drawn::fixed(40.0)),
            grid: Grid::Odd,
            phases: Phases::Random,
            level: Level::Rms(Drawn::fixed(1.0)),
            spectrum: Some(falling()),
        };
        let u = filled(&design, 0.01, n, 0);
        let reference = line_power(&u, 39); // 9.75 Hz: level 1
        for k in 4..=160 {
            let f = k as f64 * 0.25;
            let expected = if k % 2 == 1 {
                let level = if f <= 10.0 {
                    1.0
                } else {
                    1.0 - 0.5 * (f - 10.0) / 30.0
                };
                level * level
            } else {
                0.0
            };
            let got = line_power(&u, k) / reference;
            assert!(
                (got - expected).abs() < 1e-9,
                "line {k} ({f} Hz): {got} vs {expected}"
            );
        }
    }

    #[test]
    fn shaped_noise_has_its_level_on_average_and_its_shape() {
        let n = 400;
        let design = Design::ShapedNoise {
            band: (Drawn::fixed(0.0), Drawn::fixed(40.0)),
            spectrum: falling(),
            rms: Drawn::fixed(2.0),
        };
        let records: Vec<Vec<f64>> = (0..400).map(|e| filled(&design, 0.01, n, e)).collect();
        let variance = records.iter().flatten().map(|v| v * v).sum::<f64>() / (400 * n) as f64;
        // 400 records of 159 lines' two Gaussian coordinates: a relative
        // standard error near 0.4% on the variance.
        assert!((variance / 4.0 - 1.0).abs() < 0.02, "variance {variance}");
        let mean_power = |k: usize| records.iter().map(|u| line_power(u, k)).sum::<f64>();
        // Lines at 5 Hz (level 1) and 40 Hz (level 0.5), over 400 draws of
        // an exponential power each: within 10% of the ratio 0.25.
        let ratio =
            (150..=159).map(mean_power).sum::<f64>() / (16..=25).map(mean_power).sum::<f64>();
        let expected = (150..=159)
            .map(|k| {
                let level = 1.0 - 0.5 * (k as f64 * 0.25 - 10.0) / 30.0;
                level * level
            })
            .sum::<f64>()
            / 10.0;
        assert!(
            (ratio / expected - 1.0).abs() < 0.1,
            "{ratio} vs {expected}"
        );
        assert_eq!(records[3], filled(&design, 0.01, n, 3));
        assert_ne!(records[3], records[4]);
    }

    #[test]
    fn tables_that_no_record_could_use_are_refused() {
        for (points, says) in [
            (vec![], "one or more"),
            (vec![[1.0, 1.0], [1.0, 2.0]], "rising frequency"),
            (vec![[2.0, 1.0], [1.0, 2.0]], "rising frequency"),
            (vec![[0.0, -1.0]], ">= 0"),
            (vec![[f64::NAN, 1.0]], ">= 0"),
            (vec![[0.0, 0.0], [5.0, 0.0]], "every amplitude is zero"),
        ] {
            let e = Spectrum::table(points.clone()).unwrap_err().to_string();
            assert!(e.contains(says), "{points:?}: {e}");
        }
        let table = falling();
        assert!(table.check(0.01).is_ok());
        let e = table.check(0.02).unwrap_err().to_string();
        assert!(
            e.contains("40 Hz") && e.contains("Nyquist frequency 25 Hz"),
            "{e}"
        );
    }

    #[test]
    fn a_record_without_a_shape_is_refused() {
        let varying = |n: usize| (0..n).map(|t| (t as f64).sin()).collect::<Vec<f64>>();
        let short = Spectrum::like(&varying(16)).unwrap_err().to_string();
        assert!(
            short.contains("too short") && short.contains("17 samples or more"),
            "{short}"
        );
        assert_eq!(Spectrum::like(&varying(17)).unwrap().points().len(), 2);
        let flat = Spectrum::like(&[3.0; 100]).unwrap_err().to_string();
        assert!(flat.contains("does not vary"), "{flat}");
        let mut broken = vec![0.0; 100];
        broken[7] = f64::INFINITY;
        let e = Spectrum::like(&broken).unwrap_err().to_string();
        assert!(e.contains("sample 7"), "{e}");
    }

    #[test]
    fn a_band_whose_lines_are_all_zero_is_refused() {
        let zero_top = Spectrum::table(vec![[0.0, 1.0], [10.0, 0.0]]).unwrap();
        let design = Design::Multisine {
            band: (Drawn::fixed(20.0), Drawn::fixed(40.0)),
            grid: Grid::Full,
            phases: Phases::Random,
            level: Level::Rms(Drawn::fixed(1.0)),
            spectrum: Some(zero_top),
        };
        let mut u = vec![0.0; 400];
        let e = design
            .fill(0.01, &mut experiment_rng(1, 0), &mut u)
            .unwrap_err()
            .to_string();
        assert!(e.contains("zero on every line"), "{e}");
    }
}
