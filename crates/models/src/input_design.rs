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
        band: (Drawn, Drawn),
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
        from: Drawn,
        to: Drawn,
        amplitude: Drawn,
    },
    Steps {
        level: (f64, f64),
        hold: (f64, f64),
    },
    FilteredNoise {
        band: (Drawn, Drawn),
        order: u32,
        rms: Drawn,
    },
    /// Gaussian noise whose lines on the full grid in the band have
    /// amplitudes shaped by `spectrum`: periodic over the record.
    ShapedNoise {
        band: (Drawn, Drawn),
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
                bottom_below_top("multisine band", band)?;
                if let Some(spectrum) = spectrum {
                    spectrum.check(sample_time)?;
                }
                above("multisine band top", band.1.range().1)
            }
            Self::ShapedNoise { band, spectrum, .. } => {
                bottom_below_top("noise band", band)?;
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
                if from.range().0 < 0.0 {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "sweep start",
                        value: from.describe(" Hz"),
                        reason: "give a frequency >= 0".into(),
                    }));
                }
                above("sweep end", to.range().1)
            }
            Self::FilteredNoise { band, order, .. } => {
                bottom_below_top("noise band", band)?;
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
            let (lowest, highest) = band.0.range();
            let resolution = 1.0 / (n as f64 * sample_time);
            if lowest < highest && lowest < resolution {
                return Err(SimError::InvalidSetting(InvalidSetting {
                    name: "noise band bottom",
                    value: format!("[{lowest}, {highest}] Hz"),
                    reason: format!(
                        "drawn per experiment, it may fall below the record's resolution \
                         1/(N T) = {resolution} Hz (N = {n}): draw it from {resolution} Hz up, \
                         or give 0 for no lower edge"
                    ),
                }));
            }
            resolved_band(lowest, band.1.range().0, sample_time, n)?;
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
                "{} multisine on the {} grid from {} to {}, {}{}",
                match phases {
                    Phases::Random => "random-phase",
                    Phases::Schroeder => "Schroeder-phase",
                },
                match grid {
                    Grid::Full => "full",
                    Grid::Odd => "odd",
                },
                band.0.describe(" Hz"),
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
                "linear sweep from {} to {} over the record, amplitude {}",
                from.describe(" Hz"),
                to.describe(" Hz"),
                amplitude.describe("")
            ),
            Self::Steps { level, hold } => format!(
                "random steps, levels uniform in [{}, {}], each held {} to {} s",
                level.0, level.1, hold.0, hold.1
            ),
            Self::FilteredNoise { band, order, rms } => format!(
                "Gaussian noise through Butterworth filters of order {order} from {} to {}, \
                 RMS {} (stationary)",
                band.0.describe(" Hz"),
                band.1.describe(" Hz"),
                rms.describe("")
            ),
            Self::ShapedNoise {
                band,
                spectrum,
                rms,
            } => format!(
                "Gaussian noise on the full grid from {} to {}, {}, RMS {} (periodic over \
                 the record)",
                band.0.describe(" Hz"),
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
                let bottom = band.0.draw(rng);
                // Lines strictly inside (0, Nyquist): each a full cosine
                // whose samples' squares sum to n / 2 per unit amplitude.
                let lines = band_lines(bottom, top, *grid == Grid::Odd, n, sample_time);
                let count = lines.len() as f64;
                let amplitudes = line_amplitudes(&lines, spectrum.as_ref(), n, sample_time);
                no_lines("multisine band", bottom, top, &amplitudes, n, sample_time)?;
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
                let bottom = band.0.draw(rng);
                let lines = band_lines(bottom, top, false, n, sample_time);
                let amplitudes = line_amplitudes(&lines, Some(spectrum), n, sample_time);
                no_lines("noise band", bottom, top, &amplitudes, n, sample_time)?;
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
                let from = from.draw(rng);
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
                let bottom = band.0.draw(rng);
                resolved_band(bottom, top, sample_time, n)?;
                let mut filter = Cascade::new();
                if bottom > 0.0 {
                    filter = filter.butterworth(Pass::High, *order, bottom, sample_time)?;
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
                            value: format!("[{bottom}, {top}] Hz"),
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

/// Refuses a band whose bottom may be below zero or not below its top
/// (each end's every draw).
fn bottom_below_top(name: &'static str, band: &(Drawn, Drawn)) -> Result<()> {
    let ((lowest, highest), (top, _)) = (band.0.range(), band.1.range());
    if lowest >= 0.0 && highest < top {
        return Ok(());
    }
    Err(SimError::InvalidSetting(InvalidSetting {
        name,
        value: format!("[{:?}, {:?}]", band.0.range(), band.1.range()),
        reason: "give a lowest frequency >= 0 below the band's top".into(),
    }))
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
mod tests;
