//! Experiment designs that draw each record's input from its own stream:
//! random-phase multisines, random binary and pseudo-random binary
//! sequences, band-limited Gaussian noise, swept sines, random steps,
//! manoeuvre bursts and ramps between held levels, each with settings that may
//! themselves be drawn per experiment (a level range, a band whose top is
//! a range), so that a training chart covers a family of operating
//! conditions rather than one input.

use crate::InvalidSetting;
use std::f64::consts::PI;

use rand::{Rng, RngExt};
use rand_distr::{Distribution, StandardNormal};
use rustfft::num_complex::Complex;

use crate::butterworth::{Cascade, MAX_FILTER_ORDER, Pass};
use crate::error::{Result, SimError};
use crate::prbs::{MAX_PRBS_ORDER, prbs_taps};

mod bursts;
mod drawn;
mod ramps;
mod spectrum;

pub(crate) use bursts::Bursts;
pub use bursts::{MAX_BURSTS, Taper};
pub use drawn::Drawn;
pub(crate) use ramps::Ramps;
pub use spectrum::{LIKE_BANDS, LIKE_BINS_PER_BAND, Spectrum};
use spectrum::{band_lines, synthesize};

/// The frequency lines of a multisine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grid {
    /// Every line of the record's grid `k / (N T)` in the band.
    Full,
    /// The odd lines only: even-order nonlinear distortions then fall on
    /// lines the input leaves empty.
    Odd,
}

/// The phases of a multisine's lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phases {
    /// Independent, uniform on `[0, 2 pi)`, drawn per experiment.
    Random,
    /// Schroeder's `-pi k (k - 1) / K` (IEEE Trans. Inf. Theory 16, 1970):
    /// the same every experiment, a low crest factor.
    Schroeder,
}

/// How large a design's signal is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Level {
    /// Its root mean square over the record (about its offset).
    Rms(Drawn),
    /// Its largest absolute value over the record (about its offset).
    Peak(Drawn),
}

/// An input design: see the constructors of [`crate::InputSignal`]
/// (`multisine`, `random_binary`, `prbs`, `sweep`, `steps`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Design {
    Multisine {
        band: (f64, Drawn),
        grid: Grid,
        phases: Phases,
        level: Level,
        /// Its lines' relative amplitudes (`None`: all equal).
        spectrum: Option<Spectrum>,
    },
    RandomBinary {
        amplitude: Drawn,
        hold: usize,
    },
    Prbs {
        order: u32,
        amplitude: Drawn,
        hold: usize,
    },
    Sweep {
        from: f64,
        to: Drawn,
        amplitude: Drawn,
    },
    Steps {
        level: (f64, f64),
        hold: (f64, f64),
    },
    FilteredNoise {
        band: (f64, Drawn),
        order: u32,
        rms: Drawn,
    },
    /// Gaussian noise whose lines on the full grid in the band have
    /// amplitudes shaped by `spectrum`: periodic over the record.
    ShapedNoise {
        band: (f64, Drawn),
        spectrum: Spectrum,
        rms: Drawn,
    },
    Bursts(Bursts),
    Ramps(Ramps),
}

impl Design {
    /// Refuses settings no record could use: a band above the Nyquist
    /// frequency of `sample_time`, a hold of zero samples, a register order
    /// without taps.
    pub(crate) fn check(&self, sample_time: f64) -> Result<()> {
        let nyquist = 0.5 / sample_time;
        let above = |name: &'static str, f: f64| -> Result<()> {
            if f > nyquist {
                return Err(SimError::InvalidSetting(InvalidSetting {
                    name,
                    value: format!("{f} Hz"),
                    reason: format!(
                        "above the Nyquist frequency {nyquist} Hz of the sample time \
                         {sample_time} s: lower it, or sample faster"
                    ),
                }));
            }
            Ok(())
        };
        match self {
            Self::Multisine { band, spectrum, .. } => {
                if !(band.0 >= 0.0 && band.0 < band.1.range().0) {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "multisine band",
                        value: format!("[{}, {:?}]", band.0, band.1.range()),
                        reason: "give a lowest frequency >= 0 below the band's top".into(),
                    }));
                }
                if let Some(spectrum) = spectrum {
                    spectrum.check(sample_time)?;
                }
                above("multisine band top", band.1.range().1)
            }
            Self::ShapedNoise { band, spectrum, .. } => {
                if !(band.0 >= 0.0 && band.0 < band.1.range().0) {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "noise band",
                        value: format!("[{}, {:?}]", band.0, band.1.range()),
                        reason: "give a lowest frequency >= 0 below the band's top".into(),
                    }));
                }
                spectrum.check(sample_time)?;
                above("noise band top", band.1.range().1)
            }
            Self::RandomBinary { hold, .. } | Self::Prbs { hold, .. } if *hold == 0 => {
                Err(SimError::InvalidSetting(InvalidSetting {
                    name: "hold",
                    value: "0".into(),
                    reason: "hold each value at least 1 sample".into(),
                }))
            }
            Self::Prbs { order, .. } if !(2..=MAX_PRBS_ORDER).contains(order) => {
                Err(SimError::InvalidSetting(InvalidSetting {
                    name: "PRBS order",
                    value: order.to_string(),
                    reason: format!("give a register of 2 to {MAX_PRBS_ORDER} bits"),
                }))
            }
            Self::Sweep { from, to, .. } => {
                if !from.is_finite() || *from < 0.0 {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "sweep start",
                        value: format!("{from} Hz"),
                        reason: "give a frequency >= 0".into(),
                    }));
                }
                above("sweep end", to.range().1)
            }
            Self::FilteredNoise { band, order, .. } => {
                if !(band.0 >= 0.0 && band.0 < band.1.range().0) {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "noise band",
                        value: format!("[{}, {:?}]", band.0, band.1.range()),
                        reason: "give a lowest frequency >= 0 below the band's top".into(),
                    }));
                }
                if !(1..=MAX_FILTER_ORDER).contains(order) {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "filter order",
                        value: order.to_string(),
                        reason: format!("give an order of 1 to {MAX_FILTER_ORDER}"),
                    }));
                }
                above("noise band top", band.1.range().1)
            }
            Self::Steps { level, hold } => {
                Drawn::between(level.0, level.1)?;
                if !(hold.0 > 0.0 && hold.0 <= hold.1 && hold.1.is_finite()) {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "step hold",
                        value: format!("[{}, {}] s", hold.0, hold.1),
                        reason: "give a shortest and longest hold, 0 < shortest <= longest".into(),
                    }));
                }
                Ok(())
            }
            Self::Bursts(bursts) => bursts.check(sample_time),
            Self::Ramps(ramps) => ramps.check(),
            _ => Ok(()),
        }
    }

    /// Refuses a band noise whose edges a record of `n` samples cannot
    /// resolve (below 1 / (N T)): said before any experiment is drawn,
    /// for every top the design may draw.
    pub(crate) fn check_record(&self, sample_time: f64, n: usize) -> Result<()> {
        if let Self::FilteredNoise { band, .. } = self {
            resolved_band(band.0, band.1.range().0, sample_time, n)?;
        }
        Ok(())
    }

    /// Whether every experiment sees the same input.
    pub(crate) fn is_deterministic(&self) -> bool {
        match self {
            Self::Multisine {
                band,
                phases,
                level,
                ..
            } => {
                let (Level::Rms(l) | Level::Peak(l)) = level;
                *phases == Phases::Schroeder && fixed(band.1) && fixed(*l)
            }
            Self::Sweep { to, amplitude, .. } => fixed(*to) && fixed(*amplitude),
            _ => false,
        }
    }

    pub(crate) fn describe(&self) -> String {
        match self {
            Self::Multisine {
                band,
                grid,
                phases,
                level,
                spectrum,
            } => format!(
                "{} multisine on the {} grid from {} Hz to {}, {}{}",
                match phases {
                    Phases::Random => "random-phase",
                    Phases::Schroeder => "Schroeder-phase",
                },
                match grid {
                    Grid::Full => "full",
                    Grid::Odd => "odd",
                },
                band.0,
                band.1.describe(" Hz"),
                describe_level(level),
                spectrum
                    .as_ref()
                    .map_or_else(String::new, |s| format!(", {}", s.describe()))
            ),
            Self::RandomBinary { amplitude, hold } => format!(
                "random binary +-{}, each value held {hold} sample(s)",
                amplitude.describe("")
            ),
            Self::Prbs {
                order,
                amplitude,
                hold,
            } => format!(
                "PRBS of a {order}-bit register (period {}) +-{}, each bit held {hold} \
                 sample(s), from a random state per experiment",
                (1u64 << order) - 1,
                amplitude.describe("")
            ),
            Self::Sweep {
                from,
                to,
                amplitude,
            } => format!(
                "linear sweep from {from} Hz to {} over the record, amplitude {}",
                to.describe(" Hz"),
                amplitude.describe("")
            ),
            Self::Steps { level, hold } => format!(
                "random steps, levels uniform in [{}, {}], each held {} to {} s",
                level.0, level.1, hold.0, hold.1
            ),
            Self::FilteredNoise { band, order, rms } => format!(
                "Gaussian noise through Butterworth filters of order {order} from {} Hz to {}, \
                 RMS {} (stationary)",
                band.0,
                band.1.describe(" Hz"),
                rms.describe("")
            ),
            Self::ShapedNoise {
                band,
                spectrum,
                rms,
            } => format!(
                "Gaussian noise on the full grid from {} Hz to {}, {}, RMS {} (periodic over \
                 the record)",
                band.0,
                band.1.describe(" Hz"),
                spectrum.describe(),
                rms.describe("")
            ),
            Self::Bursts(bursts) => bursts.describe(),
            Self::Ramps(ramps) => ramps.describe(),
        }
    }

    /// Write the design's samples (about zero) into `u`.
    pub(crate) fn fill<R: Rng + ?Sized>(
        &self,
        sample_time: f64,
        rng: &mut R,
        u: &mut [f64],
    ) -> Result<()> {
        self.check(sample_time)?;
        let n = u.len();
        match self {
            Self::Multisine {
                band,
                grid,
                phases,
                level,
                spectrum,
            } => {
                let top = band.1.draw(rng);
                // Lines strictly inside (0, Nyquist): each a full cosine
                // whose samples' squares sum to n / 2 per unit amplitude.
                let lines = band_lines(band.0, top, *grid == Grid::Odd, n, sample_time);
                let count = lines.len() as f64;
                let amplitudes = line_amplitudes(&lines, spectrum.as_ref(), n, sample_time);
                no_lines("multisine band", band.0, top, &amplitudes, n, sample_time)?;
                let coefficients: Vec<Complex<f64>> = amplitudes
                    .iter()
                    .enumerate()
                    .map(|(i, a)| {
                        let phase = match phases {
                            Phases::Random => 2.0 * PI * rng.random::<f64>(),
                            Phases::Schroeder => -PI * (i as f64) * (i as f64 + 1.0) / count,
                        };
                        Complex::from_polar(*a, phase)
                    })
                    .collect();
                synthesize(&lines, &coefficients, u);
                scale_to(u, level, rng);
            }
            Self::ShapedNoise {
                band,
                spectrum,
                rms,
            } => {
                let top = band.1.draw(rng);
                let level = rms.draw(rng);
                let lines = band_lines(band.0, top, false, n, sample_time);
                let amplitudes = line_amplitudes(&lines, Some(spectrum), n, sample_time);
                no_lines("noise band", band.0, top, &amplitudes, n, sample_time)?;
                // Each line's coefficient complex Gaussian: every sample's
                // variance is the sum of the squared amplitudes.
                let power: f64 = amplitudes.iter().map(|a| a * a).sum();
                let scale = level / power.sqrt();
                let coefficients: Vec<Complex<f64>> = amplitudes
                    .iter()
                    .map(|a| {
                        let (re, im): (f64, f64) =
                            (StandardNormal.sample(rng), StandardNormal.sample(rng));
                        Complex::new(re, im) * (a * scale)
                    })
                    .collect();
                synthesize(&lines, &coefficients, u);
            }
            Self::RandomBinary { amplitude, hold } => {
                let a = amplitude.draw(rng);
                for chunk in u.chunks_mut(*hold) {
                    let value = if rng.random::<bool>() { a } else { -a };
                    chunk.fill(value);
                }
            }
            Self::Prbs {
                order,
                amplitude,
                hold,
            } => {
                let a = amplitude.draw(rng);
                let mask = (1u32 << order) - 1;
                // Any state but all zeros, per experiment.
                let mut state = rng.random_range(1..=mask);
                let taps = prbs_taps(*order);
                for chunk in u.chunks_mut(*hold) {
                    let bit = state & 1;
                    chunk.fill(if bit == 1 { a } else { -a });
                    let feedback = taps
                        .iter()
                        .fold(0u32, |acc, tap| acc ^ (state >> (order - tap)) & 1);
                    state = ((state >> 1) | (feedback << (order - 1))) & mask;
                }
            }
            Self::Sweep {
                from,
                to,
                amplitude,
            } => {
                let end = to.draw(rng);
                let a = amplitude.draw(rng);
                let duration = n as f64 * sample_time;
                for (k, v) in u.iter_mut().enumerate() {
                    let t = k as f64 * sample_time;
                    let cycles = from * t + (end - from) * t * t / (2.0 * duration);
                    *v = a * (2.0 * PI * cycles.fract()).sin();
                }
            }
            Self::FilteredNoise { band, order, rms } => {
                let top = band.1.draw(rng);
                let level = rms.draw(rng);
                resolved_band(band.0, top, sample_time, n)?;
                let mut filter = Cascade::new();
                if band.0 > 0.0 {
                    filter = filter.butterworth(Pass::High, *order, band.0, sample_time)?;
                }
                if top < 0.5 / sample_time {
                    filter = filter.butterworth(Pass::Low, *order, top, sample_time)?;
                }
                // Edges above the resolution settle within some tens of
                // records' lengths even at the highest order.
                let (energy, settling) =
                    filter.energy_and_settling(64 * n + 10_000).ok_or_else(|| {
                        SimError::InvalidSetting(InvalidSetting {
                            name: "noise band",
                            value: format!("[{}, {top}] Hz", band.0),
                            reason: "the filters do not settle: widen the band".into(),
                        })
                    })?;
                // The filter starts at rest and runs through its start-up
                // first, so the record is a stretch of stationary noise of
                // the drawn RMS.
                let scale = level / energy.sqrt();
                for _ in 0..settling {
                    let z: f64 = StandardNormal.sample(rng);
                    filter.step(z);
                }
                for v in u.iter_mut() {
                    let z: f64 = StandardNormal.sample(rng);
                    *v = scale * filter.step(z);
                }
            }
            Self::Steps { level, hold } => {
                let mut k = 0;
                while k < n {
                    let value = Drawn::between(level.0, level.1)?.draw(rng);
                    let seconds = Drawn::between(hold.0, hold.1)?.draw(rng);
                    let samples = ((seconds / sample_time).round() as usize).max(1);
                    let end = (k + samples).min(n);
                    u[k..end].fill(value);
                    k = end;
                }
            }
            Self::Bursts(bursts) => bursts.fill(sample_time, rng, u)?,
            Self::Ramps(ramps) => ramps.fill(sample_time, rng, u)?,
        }
        Ok(())
    }
}

/// Each line's relative amplitude: 1, or the spectrum's at its frequency.
fn line_amplitudes(
    lines: &[usize],
    spectrum: Option<&Spectrum>,
    n: usize,
    sample_time: f64,
) -> Vec<f64> {
    let df = 1.0 / (n as f64 * sample_time);
    lines
        .iter()
        .map(|&k| spectrum.map_or(1.0, |s| s.level_at(k as f64 * df, sample_time)))
        .collect()
}

/// Refuses a band in which no line of the record's grid has an amplitude.
fn no_lines(
    name: &'static str,
    low: f64,
    top: f64,
    amplitudes: &[f64],
    n: usize,
    sample_time: f64,
) -> Result<()> {
    if amplitudes.iter().any(|a| *a > 0.0) {
        return Ok(());
    }
    let df = 1.0 / (n as f64 * sample_time);
    let reason = if amplitudes.is_empty() {
        format!(
            "holds no line of the record's grid (spacing 1/(N T) = {df} Hz for N = {n}): widen \
             the band or lengthen the record"
        )
    } else {
        "its spectrum is zero on every line of the band: give it a level above zero there"
            .to_string()
    };
    Err(SimError::InvalidSetting(InvalidSetting {
        name,
        value: format!("[{low}, {top}] Hz"),
        reason,
    }))
}

fn fixed(d: Drawn) -> bool {
    d.is_fixed()
}

fn describe_level(level: &Level) -> String {
    match level {
        Level::Rms(l) => format!("RMS {}", l.describe("")),
        Level::Peak(l) => format!("peak {}", l.describe("")),
    }
}

/// Scale `u` (about zero) to the drawn level.
fn scale_to<R: Rng + ?Sized>(u: &mut [f64], level: &Level, rng: &mut R) {
    let (target, now) = match level {
        Level::Rms(l) => (
            l.draw(rng),
            (u.iter().map(|v| v * v).sum::<f64>() / u.len().max(1) as f64).sqrt(),
        ),
        Level::Peak(l) => (l.draw(rng), u.iter().fold(0.0f64, |m, v| m.max(v.abs()))),
    };
    if now > 0.0 {
        for v in u.iter_mut() {
            *v *= target / now;
        }
    }
}

/// A band noise's edges against the resolution 1 / (N T) of a record of
/// `n` samples every `sample_time` s (a bottom edge of 0 is no edge).
fn resolved_band(bottom: f64, top: f64, sample_time: f64, n: usize) -> Result<()> {
    let resolution = 1.0 / (n as f64 * sample_time);
    if top >= resolution && (bottom == 0.0 || bottom >= resolution) {
        return Ok(());
    }
    Err(SimError::InvalidSetting(InvalidSetting {
        name: "noise band",
        value: format!("[{bottom}, {top}] Hz"),
        reason: format!(
            "an edge lies below the record's resolution 1/(N T) = {resolution} Hz (N = {n}): \
             raise it, or lengthen the record"
        ),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::experiment_rng;
    use rustfft::FftPlannerScalar;

    fn filled(design: &Design, sample_time: f64, n: usize, experiment: u64) -> Vec<f64> {
        let mut u = vec![0.0; n];
        design
            .fill(sample_time, &mut experiment_rng(5, experiment), &mut u)
            .unwrap();
        u
    }

    /// The power of `u` at grid line `k`, by a direct DFT (the second
    /// algorithm beside the FFT that made it).
    fn line_power(u: &[f64], k: usize) -> f64 {
        let n = u.len() as f64;
        let (mut re, mut im) = (0.0, 0.0);
        for (t, v) in u.iter().enumerate() {
            let angle = 2.0 * PI * (k * t % u.len()) as f64 / n;
            re += v * angle.cos();
            im -= v * angle.sin();
        }
        (re * re + im * im) / (n * n)
    }

    #[test]
    fn a_multisine_has_its_lines_in_its_band_and_its_level() {
        let (n, dt) = (512, 0.01);
        let odd = Design::Multisine {
            band: (2.0, Drawn::fixed(20.0)),
            grid: Grid::Odd,
            phases: Phases::Random,
            level: Level::Rms(Drawn::fixed(0.7)),
            spectrum: None,
        };
        let u = filled(&odd, dt, n, 0);
        let rms = (u.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        assert!((rms - 0.7).abs() < 1e-12, "{rms}");
        // Grid spacing 1 / (512 * 0.01) = 0.1953 Hz: lines 11..=102 in band.
        let band = |k: usize| (11..=102).contains(&k);
        let powers: Vec<f64> = (1..n / 2).map(|k| line_power(&u, k)).collect();
        let total: f64 = powers.iter().sum();
        for (i, p) in powers.iter().enumerate() {
            let k = i + 1;
            if band(k) && k % 2 == 1 {
                // Equal lines: each a 1/46 share of the power.
                assert!((p / total - 1.0 / 46.0).abs() < 1e-9, "line {k}: {p}");
            } else {
                assert!(*p < 1e-20 * total, "line {k} outside: {p}");
            }
        }
        // Another experiment, other phases; the same one, the same bits.
        assert_ne!(u, filled(&odd, dt, n, 1));
        assert_eq!(u, filled(&odd, dt, n, 0));
    }

    #[test]
    fn schroeder_phases_lower_the_crest_factor_and_a_peak_level_holds() {
        let (n, dt) = (1024, 1.0);
        let crest = |phases| {
            let d = Design::Multisine {
                band: (0.0, Drawn::fixed(0.2)),
                grid: Grid::Full,
                phases,
                level: Level::Peak(Drawn::fixed(1.0)),
                spectrum: None,
            };
            let u = filled(&d, dt, n, 3);
            let peak = u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!((peak - 1.0).abs() < 1e-12);
            peak / (u.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt()
        };
        let (schroeder, random) = (crest(Phases::Schroeder), crest(Phases::Random));
        assert!(
            schroeder < 2.0 && schroeder < random,
            "{schroeder} vs {random}"
        );
    }

    #[test]
    fn prbs_registers_are_maximal() {
        for order in 2..=MAX_PRBS_ORDER {
            let period = (1usize << order) - 1;
            let d = Design::Prbs {
                order,
                amplitude: Drawn::fixed(1.0),
                hold: 1,
            };
            let u = filled(&d, 1.0, 2 * period, u64::from(order));
            // Periodic with 2^n - 1 bits, and no shorter period that
            // divides it; one more +1 than -1 per period.
            assert_eq!(u[..period], u[period..], "order {order}");
            let ones = u[..period].iter().filter(|v| **v > 0.0).count();
            assert_eq!(2 * ones, period + 1, "order {order}");
            for p in (1..period).filter(|p| period.is_multiple_of(*p)) {
                assert_ne!(u[..period], u[p..p + period], "order {order}: period {p}");
            }
        }
    }

    #[test]
    fn binary_steps_and_sweeps_keep_their_settings() {
        let binary = Design::RandomBinary {
            amplitude: Drawn::between(0.5, 2.0).unwrap(),
            hold: 4,
        };
        let u = filled(&binary, 1.0, 400, 0);
        let a = u[0].abs();
        assert!((0.5..=2.0).contains(&a));
        assert!(u.iter().all(|v| v.abs().to_bits() == a.to_bits()));
        assert!(
            u.chunks(4)
                .all(|c| c.iter().all(|v| v.to_bits() == c[0].to_bits()))
        );
        let steps = Design::Steps {
            level: (1.0, 3.5),
            hold: (2.0, 5.0),
        };
        let s = filled(&steps, 0.5, 1000, 2);
        let mut runs: Vec<usize> = vec![1];
        for w in s.windows(2) {
            if w[0].to_bits() == w[1].to_bits() {
                *runs.last_mut().unwrap() += 1;
            } else {
                runs.push(1);
            }
        }
        // Holds of 4 to 10 samples (the last may be cut by the record).
        assert!(
            runs[..runs.len() - 1].iter().all(|r| (4..=10).contains(r)),
            "{runs:?}"
        );
        assert!(s.iter().all(|v| (1.0..=3.5).contains(v)));
        // A sweep from 0 to 5 Hz over 10 s crosses zero about 2 * 25 times
        // (its mean frequency 2.5 Hz).
        let sweep = Design::Sweep {
            from: 0.0,
            to: Drawn::fixed(5.0),
            amplitude: Drawn::fixed(1.0),
        };
        let w = filled(&sweep, 0.001, 10_000, 0);
        let crossings = w.windows(2).filter(|p| p[0] < 0.0 && p[1] >= 0.0).count();
        assert!((24..=26).contains(&crossings), "{crossings}");
    }

    /// Filtered noise has its level and its band: the sample variance of
    /// a long record is the drawn RMS squared, and the power outside the
    /// band is what the filters' closed-form response lets through.
    #[test]
    fn filtered_noise_keeps_its_level_and_its_band() {
        let (n, dt) = (1 << 15, 0.01);
        let design = Design::FilteredNoise {
            band: (5.0, Drawn::fixed(10.0)),
            order: 6,
            rms: Drawn::fixed(2.0),
        };
        let records: Vec<Vec<f64>> = (0..4).map(|i| filled(&design, dt, n, i)).collect();
        let variance = records.iter().flatten().map(|v| v * v).sum::<f64>() / (4 * n) as f64;
        // A 5 Hz band over 4 records of 328 s: about 13,000 independent
        // samples, a relative standard error of 0.0125 on the variance.
        assert!((variance / 4.0 - 1.0).abs() < 0.05, "variance {variance}");
        // The lines of the record's grid well outside [5, 10] Hz hold a
        // small share of the power, as 1 / (1 + ratio^12) says.
        let mut spectrum: Vec<Complex<f64>> =
            records[0].iter().map(|v| Complex::new(*v, 0.0)).collect();
        FftPlannerScalar::new()
            .plan_fft_forward(n)
            .process(&mut spectrum);
        let df = 1.0 / (n as f64 * dt);
        let (mut inside, mut outside) = (0.0, 0.0);
        for (k, line) in spectrum.iter().enumerate().take(n / 2).skip(1) {
            let f = k as f64 * df;
            let p = line.norm_sqr();
            if (5.0..=10.0).contains(&f) {
                inside += p;
            } else if !(3.5..=14.0).contains(&f) {
                outside += p;
            }
        }
        assert!(
            outside < 0.01 * inside,
            "{outside} outside, {inside} inside"
        );
        // The start is already stationary: over 400 experiments the first
        // sample's mean square is the level's (a filter started at rest
        // would begin near 0). Its relative standard error is 0.07.
        let first = (0..400)
            .map(|i| filled(&design, dt, 256, i)[0].powi(2))
            .sum::<f64>()
            / 400.0;
        assert!(
            (first / 4.0 - 1.0).abs() < 0.25,
            "first samples' mean square {first}"
        );
        // An edge below the record's resolution, and an order out of range.
        let coarse = Design::FilteredNoise {
            band: (0.0, Drawn::fixed(0.5)),
            order: 4,
            rms: Drawn::fixed(1.0),
        };
        let mut short = vec![0.0; 100];
        let e = coarse
            .fill(dt, &mut experiment_rng(5, 0), &mut short)
            .unwrap_err()
            .to_string();
        assert!(e.contains("resolution") && e.contains("1 Hz"), "{e}");
        let steep = Design::FilteredNoise {
            band: (0.0, Drawn::fixed(5.0)),
            order: 11,
            rms: Drawn::fixed(1.0),
        };
        assert!(steep.check(dt).unwrap_err().to_string().contains("1 to 10"));
    }

    #[test]
    fn impossible_designs_are_refused_with_what_would_work() {
        let high = Design::Multisine {
            band: (0.0, Drawn::fixed(60.0)),
            grid: Grid::Full,
            phases: Phases::Random,
            level: Level::Rms(Drawn::fixed(1.0)),
            spectrum: None,
        };
        let e = high.check(0.01).unwrap_err().to_string();
        assert!(e.contains("above the Nyquist frequency 50 Hz"), "{e}");
        let narrow = Design::Multisine {
            band: (1.2, Drawn::fixed(1.5)),
            grid: Grid::Full,
            phases: Phases::Random,
            level: Level::Rms(Drawn::fixed(1.0)),
            spectrum: None,
        };
        let mut u = vec![0.0; 100];
        let e = narrow
            .fill(0.01, &mut experiment_rng(0, 0), &mut u)
            .unwrap_err()
            .to_string();
        assert!(e.contains("holds no line of the record's grid"), "{e}");
        assert!(Drawn::between(2.0, 1.0).is_err());
        let held = Design::RandomBinary {
            amplitude: Drawn::fixed(1.0),
            hold: 0,
        };
        assert!(
            held.check(1.0)
                .unwrap_err()
                .to_string()
                .contains("at least 1 sample")
        );
        let order = Design::Prbs {
            order: 40,
            amplitude: Drawn::fixed(1.0),
            hold: 1,
        };
        assert!(order.check(1.0).is_err());
    }
}
