//! Random manoeuvres: an input that rests, then drives the system with a
//! short sine burst, and rests again, a few times per record. Ordinary
//! operation is like that (a car's steering between lane changes and
//! turns, a valve opened and closed), and a family of stationary noise
//! never shows stage 1 a record that starts from rest or settles back:
//! an estimator trained on it extrapolates on every standard manoeuvre.
//!
//! Each burst is `a sin(2 pi c x) w(x)` for `x = (t - start) / length` in
//! `[0, 1)`, with `c` a whole number of half cycles so that an untapered
//! burst ends at zero too, and `w` a Hann taper `sin(pi x)^2` or none.
//! The paper's chicane is one such burst (2 cycles over 8 s, tapered).

use std::f64::consts::PI;

use rand::{Rng, RngExt};

use super::Drawn;
use crate::error::{Result, SimError};

/// The most bursts a record may draw: beyond it the bursts overlap into
/// noise, which the `gaussian` design draws directly.
pub const MAX_BURSTS: usize = 1000;

/// The window over each burst.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taper {
    /// `sin(pi x)^2`: the burst fades in and out.
    Hann,
    /// None: the sine starts and stops at zero, with a corner.
    None,
    /// Hann or none, drawn per burst.
    Mixed,
}

/// The settings of a `bursts` input design (see the module's page).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Bursts {
    /// Bursts per record, drawn uniformly from the whole numbers between.
    pub(crate) count: (usize, usize),
    /// Each burst's length in seconds.
    pub(crate) seconds: Drawn,
    /// Sine periods per burst, drawn from the half cycles in the range.
    pub(crate) cycles: Drawn,
    /// Each burst's sine amplitude; its sign is drawn.
    pub(crate) amplitude: Drawn,
    pub(crate) taper: Taper,
}

impl Bursts {
    /// The half cycles `cycles` may draw: `2 c` from `first` to `last`.
    fn half_cycles(&self) -> Result<(u64, u64)> {
        let (low, high) = self.cycles.range();
        let (first, last) = ((2.0 * low).ceil().max(1.0), (2.0 * high).floor());
        if !(first <= last && last < 1e9) {
            return Err(SimError::InvalidSetting {
                name: "bursts cycles",
                value: format!("[{low}, {high}]"),
                reason: "holds no whole number of half cycles from 0.5 on: widen it \
                         (e.g. [0.5, 2.5])"
                    .into(),
            });
        }
        Ok((first as u64, last as u64))
    }

    /// Refuses settings no record could use; with a `sample_time` above
    /// zero, also a burst whose sine lies above the Nyquist frequency.
    pub(crate) fn check(&self, sample_time: f64) -> Result<()> {
        let (fewest, most) = self.count;
        if fewest == 0 || fewest > most || most > MAX_BURSTS {
            return Err(SimError::InvalidSetting {
                name: "bursts count",
                value: format!("[{fewest}, {most}]"),
                reason: format!(
                    "give whole numbers of bursts per record, 1 <= low <= high <= {MAX_BURSTS}"
                ),
            });
        }
        let (shortest, _) = self.seconds.range();
        if shortest <= 0.0 {
            return Err(SimError::InvalidSetting {
                name: "bursts seconds",
                value: shortest.to_string(),
                reason: "a burst lasts a positive time".into(),
            });
        }
        let (_, most_half_cycles) = self.half_cycles()?;
        let fastest = most_half_cycles as f64 / 2.0 / shortest;
        if sample_time > 0.0 && fastest > 0.5 / sample_time {
            return Err(SimError::InvalidSetting {
                name: "bursts",
                value: format!("{} cycles in {shortest} s", most_half_cycles as f64 / 2.0),
                reason: format!(
                    "a sine of {fastest} Hz lies above the Nyquist frequency {} Hz of the \
                     sample time {sample_time} s: fewer cycles or longer bursts",
                    0.5 / sample_time
                ),
            });
        }
        Ok(())
    }

    pub(crate) fn describe(&self) -> String {
        let between = |(low, high): (f64, f64)| {
            if low.to_bits() == high.to_bits() {
                low.to_string()
            } else {
                format!("{low} to {high}")
            }
        };
        let (fewest, most) = self.count;
        format!(
            "random bursts, {} per record, each a sine of {} cycles (in whole half cycles) \
             over {} s, amplitude {} of a random sign, {}, at a random time wholly in the \
             record (one longer than the record from its start), each drawn per burst",
            between((fewest as f64, most as f64)),
            between(self.cycles.range()),
            between(self.seconds.range()),
            between(self.amplitude.range()),
            match self.taper {
                Taper::Hann => "Hann-tapered",
                Taper::None => "untapered",
                Taper::Mixed => "Hann-tapered or not",
            }
        )
    }

    /// Add the record's bursts (about zero) into `u`, zeroed first.
    pub(crate) fn fill<R: Rng + ?Sized>(
        &self,
        sample_time: f64,
        rng: &mut R,
        u: &mut [f64],
    ) -> Result<()> {
        let (first, last) = self.half_cycles()?;
        u.fill(0.0);
        let record = u.len() as f64 * sample_time;
        let count = rng.random_range(self.count.0..=self.count.1);
        for _ in 0..count {
            let length = self.seconds.draw(rng);
            let cycles = rng.random_range(first..=last) as f64 / 2.0;
            let amplitude =
                self.amplitude.draw(rng) * if rng.random::<bool>() { 1.0 } else { -1.0 };
            let tapered = match self.taper {
                Taper::Hann => true,
                Taper::None => false,
                Taper::Mixed => rng.random::<bool>(),
            };
            let start = rng.random::<f64>() * (record - length).max(0.0);
            for (k, v) in u.iter_mut().enumerate() {
                let x = (k as f64 * sample_time - start) / length;
                if (0.0..1.0).contains(&x) {
                    let taper = if tapered { (PI * x).sin().powi(2) } else { 1.0 };
                    *v += amplitude * (2.0 * PI * cycles * x).sin() * taper;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment_rng;

    fn bursts(count: (usize, usize), cycles: Drawn, taper: Taper) -> Bursts {
        Bursts {
            count,
            seconds: Drawn::between(2.0, 8.0).unwrap(),
            cycles,
            amplitude: Drawn::between(0.05, 0.2).unwrap(),
            taper,
        }
    }

    /// Runs of nonzero samples: the bursts one finds in the record.
    fn runs(u: &[f64]) -> Vec<(usize, usize)> {
        let mut found = Vec::new();
        let mut start = None;
        for (k, v) in u.iter().chain([&0.0]).enumerate() {
            match (start, *v != 0.0) {
                (None, true) => start = Some(k),
                (Some(s), false) => {
                    found.push((s, k));
                    start = None;
                }
                _ => {}
            }
        }
        found
    }

    #[test]
    fn one_burst_is_a_whole_number_of_half_sines_between_rests() {
        let design = bursts((1, 1), Drawn::between(0.5, 2.5).unwrap(), Taper::None);
        let dt = 0.02;
        for experiment in 0..50 {
            let mut u = vec![1.0; 500];
            design
                .fill(dt, &mut experiment_rng(7, experiment), &mut u)
                .unwrap();
            // The span from the first to the last nonzero sample (a zero
            // crossing landing on a sample splits the run, not the burst).
            let found = runs(&u);
            let (start, end) = (found[0].0, found.last().unwrap().1);
            let inside: Vec<f64> = u[start..end]
                .iter()
                .copied()
                .filter(|v| *v != 0.0)
                .collect();
            let crossings = inside.windows(2).filter(|w| w[0] * w[1] < 0.0).count();
            let peak = inside.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(peak <= 0.2 + 1e-12, "{experiment}: {peak}");
            assert!(crossings <= 4, "{experiment}: {crossings} sign changes");
            let seconds = (end - start) as f64 * dt;
            // Wholly in the record: its drawn length, and a crest of at
            // least the least amplitude (to the grid's miss of it).
            assert!(
                (2.0 - dt..=8.0 + dt).contains(&seconds),
                "{experiment}: {seconds}"
            );
            assert!(peak >= 0.05 * 0.999, "{experiment}: {peak}");
        }
    }

    #[test]
    fn a_tapered_burst_of_fixed_settings_is_the_closed_form() {
        // Two cycles over 8 s, tapered: the chicane's shape.
        let design = Bursts {
            count: (1, 1),
            seconds: Drawn::fixed(8.0),
            cycles: Drawn::fixed(2.0),
            amplitude: Drawn::fixed(0.2),
            taper: Taper::Hann,
        };
        let dt = 0.02;
        let mut u = vec![0.0; 500];
        let mut rng = experiment_rng(3, 1);
        design.fill(dt, &mut rng, &mut u).unwrap();
        let start = u.iter().position(|v| *v != 0.0).unwrap() as f64 * dt;
        // The closed form from the burst's own start, to within the one
        // sample of its start the grid hides: compare the shape where a
        // shift of a sample changes it by less than the tolerance.
        let sign = u.iter().find(|v| v.abs() > 1e-3).unwrap().signum();
        let shifted = |s: f64| -> f64 {
            (0..500)
                .map(|k| {
                    let x = (k as f64 * dt - s) / 8.0;
                    let want = if (0.0..1.0).contains(&x) {
                        sign * 0.2 * (4.0 * PI * x).sin() * (PI * x).sin().powi(2)
                    } else {
                        0.0
                    };
                    (u[k] - want).abs()
                })
                .fold(0.0, f64::max)
        };
        let best = (0..=100)
            .map(|i| shifted(start - dt + i as f64 * dt / 100.0))
            .fold(f64::INFINITY, f64::min);
        assert!(best < 2e-4, "{best}");
    }

    #[test]
    fn settings_no_record_could_use_are_refused() {
        let ok = Drawn::between(0.5, 2.5).unwrap();
        assert!(bursts((0, 2), ok, Taper::Mixed).check(0.02).is_err());
        assert!(bursts((3, 2), ok, Taper::Mixed).check(0.02).is_err());
        let no_half = Drawn::between(0.6, 0.9).unwrap();
        let err = bursts((1, 2), no_half, Taper::Mixed)
            .check(0.02)
            .unwrap_err();
        assert!(err.to_string().contains("half cycles"), "{err}");
        // 2.5 cycles in 2 s is 1.25 Hz: above the Nyquist frequency of 1 s.
        let err = bursts((1, 2), ok, Taper::Mixed).check(1.0).unwrap_err();
        assert!(err.to_string().contains("Nyquist"), "{err}");
        assert!(bursts((1, 2), ok, Taper::Mixed).check(0.02).is_ok());
    }

    #[test]
    fn the_same_stream_draws_the_same_record() {
        let design = bursts((1, 3), Drawn::between(0.5, 2.5).unwrap(), Taper::Mixed);
        let (mut a, mut b, mut c) = (vec![0.0; 300], vec![0.0; 300], vec![0.0; 300]);
        design
            .fill(0.02, &mut experiment_rng(1, 4), &mut a)
            .unwrap();
        design
            .fill(0.02, &mut experiment_rng(1, 4), &mut b)
            .unwrap();
        design
            .fill(0.02, &mut experiment_rng(1, 5), &mut c)
            .unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
