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
//!
//! A burst may dwell: its sine stops at one of its crests (drawn) for a
//! drawn time and then goes on, as the sine with dwell of FMVSS 126 holds
//! its second crest, and a turn held at its crest is a steady corner.
//! Stationary bursts never hold a system at its crest long enough to
//! settle there, and where the system saturates that is where its
//! parameters show.

use crate::InvalidSetting;
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
    /// Seconds each burst holds one of its crests; exactly zero draws
    /// nothing (the records of a design without dwells stay as they were).
    pub(crate) dwell: Drawn,
}

impl Bursts {
    /// The half cycles `cycles` may draw: `2 c` from `first` to `last`.
    fn half_cycles(&self) -> Result<(u64, u64)> {
        let (low, high) = self.cycles.range();
        let (first, last) = ((2.0 * low).ceil().max(1.0), (2.0 * high).floor());
        if !(first <= last && last < 1e9) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "bursts cycles",
                value: format!("[{low}, {high}]"),
                reason: "holds no whole number of half cycles from 0.5 on: widen it \
                         (e.g. [0.5, 2.5])"
                    .into(),
            }));
        }
        Ok((first as u64, last as u64))
    }

    /// Refuses settings no record could use; with a `sample_time` above
    /// zero, also a burst whose sine lies above the Nyquist frequency.
    pub(crate) fn check(&self, sample_time: f64) -> Result<()> {
        let (fewest, most) = self.count;
        if fewest == 0 || fewest > most || most > MAX_BURSTS {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "bursts count",
                value: format!("[{fewest}, {most}]"),
                reason: format!(
                    "give whole numbers of bursts per record, 1 <= low <= high <= {MAX_BURSTS}"
                ),
            }));
        }
        self.seconds
            .check_low("bursts seconds", 0.0, true, "a burst lasts a positive time")?;
        let (shortest, _) = self.seconds.range();
        self.dwell.check_low(
            "bursts dwell",
            0.0,
            false,
            "a crest is held zero seconds or more (e.g. [0, 1.5])",
        )?;
        let (_, most_half_cycles) = self.half_cycles()?;
        let fastest = most_half_cycles as f64 / 2.0 / shortest;
        if sample_time > 0.0 && fastest > 0.5 / sample_time {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "bursts",
                value: format!("{} cycles in {shortest} s", most_half_cycles as f64 / 2.0),
                reason: format!(
                    "a sine of {fastest} Hz lies above the Nyquist frequency {} Hz of the \
                     sample time {sample_time} s: fewer cycles or longer bursts",
                    0.5 / sample_time
                ),
            }));
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
        let dwell = if self.dwells() {
            format!(", holding a random crest {} s", between(self.dwell.range()))
        } else {
            String::new()
        };
        format!(
            "random bursts, {} per record, each a sine of {} cycles (in whole half cycles) \
             over {} s, amplitude {} of a random sign, {}{dwell}, at a random time wholly \
             in the record (one longer than the record from its start), each drawn per burst",
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

    fn dwells(&self) -> bool {
        self.dwell.range().1 > 0.0
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
            // The crest held and for how long, as a fraction of the burst:
            // crest j of the sine lies at x = (2 j + 1) / (4 c).
            let (crest, hold) = if self.dwells() {
                let half_cycles = (2.0 * cycles) as u64;
                let j = rng.random_range(0..half_cycles) as f64;
                (
                    (2.0 * j + 1.0) / (4.0 * cycles),
                    self.dwell.draw(rng) / length,
                )
            } else {
                (1.0, 0.0)
            };
            let start = rng.random::<f64>() * (record - length * (1.0 + hold)).max(0.0);
            for (k, v) in u.iter_mut().enumerate() {
                let held = (k as f64 * sample_time - start) / length;
                let x = if held < crest {
                    held
                } else if held < crest + hold {
                    crest
                } else {
                    held - hold
                };
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
            dwell: Drawn::fixed(0.0),
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
            dwell: Drawn::fixed(0.0),
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
    fn a_dwelling_burst_holds_a_crest_and_goes_on_as_the_sine_with_dwell() {
        // FMVSS 126's shape: one cycle of 0.7 Hz, a crest held 0.5 s.
        let period = 1.0 / 0.7;
        let design = Bursts {
            count: (1, 1),
            seconds: Drawn::fixed(period),
            cycles: Drawn::fixed(1.0),
            amplitude: Drawn::fixed(0.2),
            taper: Taper::None,
            dwell: Drawn::fixed(0.5),
        };
        let dt = 0.02;
        let mut crests_held = [0; 2];
        for experiment in 0..40 {
            let mut u = vec![0.0; 500];
            design
                .fill(dt, &mut experiment_rng(5, experiment), &mut u)
                .unwrap();
            let first = u.iter().position(|v| *v != 0.0).unwrap();
            let last = u.iter().rposition(|v| *v != 0.0).unwrap();
            let seconds = (last + 1 - first) as f64 * dt;
            assert!(
                (period + 0.5 - dt..=period + 0.5 + dt).contains(&seconds),
                "{experiment}: {seconds}"
            );
            // The held samples sit at the crest; the sine's own samples
            // reach it at most once per crest.
            let held: Vec<usize> = (first..=last)
                .filter(|&k| (u[k].abs() - 0.2).abs() < 1e-12)
                .collect();
            assert!((25..=27).contains(&held.len()), "{experiment}: {held:?}");
            assert!(held.windows(2).all(|w| w[1] == w[0] + 1), "{held:?}");
            // Before the hold: the sine from the burst's start; the first
            // crest held is a quarter period in, the second three.
            let quarter = ((held[0] - first) as f64 * dt / (period / 4.0)).round() as i64;
            assert!(quarter == 1 || quarter == 3, "{experiment}: {quarter}");
            crests_held[usize::from(quarter == 3)] += 1;
            let sign = u[held[0]].signum() * if quarter == 3 { -1.0 } else { 1.0 };
            let start = (first as f64 - 1.0) * dt;
            let shape = |s: f64| -> f64 {
                (first..held[0])
                    .chain(held[held.len() - 1] + 1..=last)
                    .map(|k| {
                        let mut t = k as f64 * dt - s;
                        if k > held[0] {
                            t -= 0.5;
                        }
                        (u[k] - sign * 0.2 * (std::f64::consts::TAU * t / period).sin()).abs()
                    })
                    .fold(0.0, f64::max)
            };
            let best = (0..=100)
                .map(|i| shape(start + i as f64 * dt / 100.0))
                .fold(f64::INFINITY, f64::min);
            assert!(best < 3e-3, "{experiment}: {best}");
        }
        assert!(crests_held.iter().all(|&n| n > 5), "{crests_held:?}");
    }

    #[test]
    fn a_design_without_dwells_draws_what_it_drew_before_dwells_existed() {
        // The stream a dwell-free burst consumes is its length, cycles,
        // amplitude, sign, taper and start: draw them by hand.
        let design = bursts((1, 1), Drawn::between(0.5, 2.5).unwrap(), Taper::Mixed);
        let dt = 0.02;
        let mut u = vec![0.0; 500];
        design.fill(dt, &mut experiment_rng(9, 3), &mut u).unwrap();
        let mut rng = experiment_rng(9, 3);
        let _count: usize = rng.random_range(1..=1);
        let length = design.seconds.draw(&mut rng);
        let cycles = rng.random_range(1..=5u64) as f64 / 2.0;
        let amplitude =
            design.amplitude.draw(&mut rng) * if rng.random::<bool>() { 1.0 } else { -1.0 };
        let tapered = rng.random::<bool>();
        let start = rng.random::<f64>() * (10.0 - length);
        for (k, v) in u.iter().enumerate() {
            let x = (k as f64 * dt - start) / length;
            let want = if (0.0..1.0).contains(&x) {
                let taper = if tapered { (PI * x).sin().powi(2) } else { 1.0 };
                amplitude * (2.0 * PI * cycles * x).sin() * taper
            } else {
                0.0
            };
            assert!((v - want).abs() < 1e-12, "{k}: {v} against {want}");
        }
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
        let mut backwards = bursts((1, 2), ok, Taper::Mixed);
        backwards.dwell = Drawn::between(-1.0, 1.0).unwrap();
        let err = backwards.check(0.02).unwrap_err();
        assert!(err.to_string().contains("dwell"), "{err}");
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
