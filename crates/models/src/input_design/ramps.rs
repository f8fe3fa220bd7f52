//! Ramps and holds: an input that rests, then moves to a level drawn per
//! change over a drawn ramp time, holds it a drawn time, and moves on.
//! A driver's steering into a steady corner, a valve opened to a setting,
//! a throttle tip-in are such moves; a ramp time of zero is a step.
//! Random steps ([`super::Design::Steps`]) start at their first level and
//! never ramp: a family of them never shows stage 1 a record that leaves
//! rest, or the slope of a move.

use rand::Rng;

use super::Drawn;
use crate::error::Result;

/// The settings of a `ramps` input design (see the module's page).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Ramps {
    /// Each level moved to, uniform per move.
    pub(crate) level: Drawn,
    /// Seconds each level (the first rest included) is held, per hold.
    pub(crate) hold: Drawn,
    /// Seconds each move takes, per move: zero is a step.
    pub(crate) ramp: Drawn,
}

impl Ramps {
    /// Refuses a hold that is not positive or a ramp below zero.
    pub(crate) fn check(&self) -> Result<()> {
        self.hold.check_low(
            "ramps hold_seconds",
            0.0,
            true,
            "a level is held a positive time (e.g. [0.5, 5])",
        )?;
        self.ramp.check_low(
            "ramps ramp_seconds",
            0.0,
            false,
            "a move takes zero seconds (a step) or more (e.g. [0, 3])",
        )?;
        Ok(())
    }

    pub(crate) fn describe(&self) -> String {
        format!(
            "ramps and holds from rest: levels uniform in [{}, {}], each held {} s, \
             reached in {} s, each drawn per move",
            self.level.range().0,
            self.level.range().1,
            between(self.hold.range()),
            between(self.ramp.range()),
        )
    }

    /// Write the record's moves (about zero) into `u`.
    pub(crate) fn fill<R: Rng + ?Sized>(
        &self,
        sample_time: f64,
        rng: &mut R,
        u: &mut [f64],
    ) -> Result<()> {
        self.check()?;
        let samples = |seconds: f64| (seconds / sample_time).round().max(0.0) as usize;
        let (mut k, mut current) = (0, 0.0);
        while k < u.len() {
            let end = (k + samples(self.hold.draw(rng)).max(1)).min(u.len());
            u[k..end].fill(current);
            k = end;
            let target = self.level.draw(rng);
            let ramp = samples(self.ramp.draw(rng));
            // Sample i of a ramp of r samples lies (i + 1) / r of the way:
            // its last sample is the new level to the bit, which the hold
            // then keeps.
            for i in 0..ramp.min(u.len() - k) {
                let way = (i + 1) as f64 / ramp as f64;
                u[k + i] = current * (1.0 - way) + target * way;
            }
            k = (k + ramp).min(u.len());
            current = target;
        }
        Ok(())
    }
}

fn between((low, high): (f64, f64)) -> String {
    if low.to_bits() == high.to_bits() {
        low.to_string()
    } else {
        format!("{low} to {high}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::experiment_rng;

    /// The moves of a record, read back from its samples: the runs of
    /// equal values (holds) and the samples between them (ramps).
    fn holds(u: &[f64]) -> Vec<(usize, usize, f64)> {
        let mut runs = Vec::new();
        let mut start = 0;
        for k in 1..=u.len() {
            if k == u.len() || u[k].to_bits() != u[start].to_bits() {
                if k - start >= 2 {
                    runs.push((start, k, u[start]));
                }
                start = k;
            }
        }
        runs
    }

    #[test]
    fn a_record_rests_then_ramps_between_held_levels() {
        let ramps = Ramps {
            level: Drawn::between(-1.0, 1.0).unwrap(),
            hold: Drawn::between(1.0, 2.0).unwrap(),
            ramp: Drawn::fixed(0.5),
        };
        let dt = 0.01;
        let mut u = vec![f64::NAN; 3000];
        ramps.fill(dt, &mut experiment_rng(4, 2), &mut u).unwrap();
        let runs = holds(&u);
        // The rest first, 100 to 200 samples at exactly zero.
        assert_eq!(runs[0].0, 0);
        assert_eq!(runs[0].2.to_bits(), 0.0f64.to_bits());
        assert!((100..=200).contains(&runs[0].1), "{runs:?}");
        for pair in runs.windows(2) {
            let ((_, end, from), (start, stop, to)) = (pair[0], pair[1]);
            // 50 ramp samples between holds, on the straight line from one
            // level to the next (a second computation of the same line).
            assert_eq!(start - end, 49, "{runs:?}");
            for (i, v) in u[end..start].iter().enumerate() {
                let want = from + (to - from) * (i + 1) as f64 / 50.0;
                assert!((v - want).abs() < 1e-12, "{i}: {v} vs {want}");
            }
            assert!((-1.0..=1.0).contains(&to));
            // Holds of 100 to 200 samples, the ramp's last one included;
            // the record may cut the last.
            let held = stop - start + 1;
            assert!(stop == u.len() || (100..=201).contains(&held), "{held}");
        }
        assert!(runs.len() >= 10, "{}", runs.len());
        // Zero ramp time: steps from rest.
        let steps = Ramps {
            ramp: Drawn::fixed(0.0),
            ..ramps.clone()
        };
        steps.fill(dt, &mut experiment_rng(4, 2), &mut u).unwrap();
        let changes = u
            .windows(2)
            .filter(|w| w[0].to_bits() != w[1].to_bits())
            .count();
        assert_eq!(changes + 1, holds(&u).len(), "every change is a step");
        assert!(
            Ramps {
                hold: Drawn::fixed(0.0),
                ..ramps.clone()
            }
            .check()
            .unwrap_err()
            .to_string()
            .contains("held a positive time")
        );
        assert!(
            Ramps {
                ramp: Drawn::between(-1.0, 1.0).unwrap(),
                ..ramps
            }
            .check()
            .is_err()
        );
    }
}
