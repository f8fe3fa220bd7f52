//! How large a search's chart is and when its search ends: from the
//! budget, a timing pilot and the chart's own pace, and the run opened on
//! them.

use std::time::{Duration, Instant};

use twostage_models::Simulator;
use twostage_sources::simulate_records;
use twostage_train::{Error, Result};
use twostage_train::{RunSettings, TwoStage};

use crate::Budget;
use crate::cost::held_out_seconds;

/// Largest chart a time budget chooses per second of budget: the default
/// search's fits, not its simulations, dominate its cost, and they grow
/// with m; the rate is the one their measured time affords, and a larger
/// one left the refit too little time for its records
/// (docs/performance.md, "The automatic design's cost constants").
const SIMULATIONS_PER_BUDGET_SECOND: f64 = 8000.0 / 120.0;

/// Memory allowed for the stored records.
const MAX_CHART_BYTES: usize = 2 << 30;

/// A search's run, opened with the chart size and deadline its budget
/// gives.
pub(crate) struct SizedRun<'a, S: ?Sized> {
    pub(crate) run: twostage_train::Run<'a, S>,
    /// Training records the search takes.
    pub(crate) m: usize,
    pub(crate) deadline: Option<Instant>,
    /// Wall seconds per simulation, where measured: the pilot's, then the
    /// search chart's ([`SizedRun::timed_chart`]).
    pub(crate) per_simulation: Option<f64>,
    /// Whether the records are simulated (else read).
    pub(crate) simulates: bool,
}

impl<S: Simulator + ?Sized> SizedRun<'_, S> {
    /// The cost of a simulation measured again on the search's chart
    /// (`simulations` in `seconds`), and the deadline moved to keep what
    /// calibration and validation take at that cost: the
    /// chart's thousands of simulations measure it better than the
    /// pilot's 64, on which a simulator's start weighs. A chart smaller
    /// than the pilot, or records
    /// read from files, keep the pilot's.
    pub(crate) fn timed_chart(&mut self, budget: Budget, start: Instant, charted: (usize, f64)) {
        if !self.simulates || self.deadline.is_none() {
            return;
        }
        let settings = self.run.settings();
        let held_out = settings.calibration + settings.validation;
        if let Some((per_simulation, search)) = search_seconds_measured(budget, charted, held_out) {
            self.per_simulation = Some(per_simulation);
            let kept = certificate_seconds(budget, settings);
            self.deadline = Some(start + Duration::from_secs_f64((search - kept).max(0.0)));
        }
    }
}

/// The share of a time budget kept for a validation that grows toward
/// its certificate ([`RunSettings::certify_within`]), where the records
/// are simulated: the search ends that much earlier, and the validation's
/// rounds take what is left before the budget's end.
const CERTIFICATE_SHARE: f64 = 0.1;

/// The seconds of `budget` kept for the certificate's growth under
/// `settings` (none for a simulation budget, a fixed validation, or
/// none at all).
fn certificate_seconds(budget: Budget, settings: &RunSettings) -> f64 {
    match budget {
        Budget::Seconds(t) if settings.certify_within.is_some() && settings.validation > 0 => {
            CERTIFICATE_SHARE * t
        }
        _ => 0.0,
    }
}

/// Under a time budget, the wall seconds a simulation takes as the chart's
/// `simulations` in `seconds` measured it, and the seconds from the run's
/// start the search may take so that `held_out` records at that cost fit
/// in the budget; none for a simulation budget or a chart smaller than
/// the pilot.
fn search_seconds_measured(
    budget: Budget,
    (simulations, seconds): (usize, f64),
    held_out: usize,
) -> Option<(f64, f64)> {
    let Budget::Seconds(t) = budget else {
        return None;
    };
    if simulations < PILOT_SIMULATIONS {
        return None;
    }
    let per_simulation = (seconds / simulations as f64).max(1e-9);
    Some((
        per_simulation,
        (t - held_out_seconds(per_simulation, held_out)).max(0.0),
    ))
}

/// Open `base`'s run for a search of `budget`. A simulated chart's size
/// follows from the budget before the run opens it; a chart or shards on
/// disk bring their own, adopted by the run.
pub(crate) fn open_run<'a, S: Simulator + ?Sized>(
    base: TwoStage<'a, S>,
    budget: Budget,
    start: Instant,
) -> Result<SizedRun<'a, S>> {
    let simulates = base.record_source().simulates();
    let (run, sized) = if simulates {
        base.run_settings().check()?;
        let sized = chart_size(
            budget,
            base.simulator(),
            base.run_settings(),
            Sizing::Simulated,
            start,
        )?;
        let asked = (
            base.run_settings().calibration,
            base.run_settings().validation,
        );
        let grown = base.run_settings().certify_within;
        let most = base.run_settings().max_validation;
        let base = match (sized.held_out, grown) {
            (Some((calibration, validation)), Some(k)) => base
                .calibration(calibration)
                .validation(validation)
                .certify_within(k, most),
            (Some((calibration, validation)), None) => {
                base.calibration(calibration).validation(validation)
            }
            (None, _) => base,
        };
        let run = base.simulations(sized.m).prepare()?;
        if let Some((calibration, validation)) = sized.held_out {
            run.progress().note(&format!(
                "the budget affords {calibration} calibration and {validation} validation \
                 records, not the {} and {} asked for (measured {:.2} ms a simulation; they \
                 count against it): a larger budget keeps them all",
                asked.0,
                asked.1,
                1e3 * sized.per_simulation.unwrap_or(0.0)
            ));
        }
        (run, sized)
    } else {
        let run = base.prepare()?;
        let sized = chart_size(budget, run.simulator(), run.settings(), Sizing::Read, start)?;
        (run, sized)
    };
    let ChartSize {
        m,
        deadline,
        per_simulation,
        ..
    } = sized;
    // The run's own rounds (a validation growing toward its certificate)
    // may take the whole budget; the search ends before them.
    let end = match budget {
        Budget::Seconds(t) if t.is_finite() && t > 0.0 => Some(start + Duration::from_secs_f64(t)),
        _ => None,
    };
    Ok(SizedRun {
        run: run.with_deadline(end),
        m,
        deadline,
        per_simulation,
        simulates,
    })
}

/// The most records of `spec`'s model a search keeps in memory.
pub(crate) fn chart_memory_cap(spec: &twostage_models::ModelSpec) -> usize {
    let record_bytes =
        spec.n_samples() * (spec.input_names().len() + spec.output_names().len()) * 8;
    (MAX_CHART_BYTES / record_bytes.max(1)).max(100)
}

/// The number of training records of a search, the deadline of its fits
/// and, for a time budget on simulated records, the pilot's wall seconds
/// per simulation. Simulated: a simulation budget as given; a time budget
/// keeps what calibration and validation will take (timed by a pilot) and
/// spends a fifth of the rest on the chart. Read from files: the first
/// training records, as many as a simulation budget says, or as a time
/// budget would simulate. Either way the records must fit in memory.
fn chart_size<S: Simulator + ?Sized>(
    budget: Budget,
    simulator: &S,
    settings: &RunSettings,
    sizing: Sizing,
    start: Instant,
) -> Result<ChartSize> {
    let simulates = sizing == Sizing::Simulated;
    let memory_cap = chart_memory_cap(simulator.spec());
    let mut per_simulation = None;
    let mut held_out_sizes = None;
    let (m, deadline) = match budget {
        Budget::Simulations(m) => (m, None),
        Budget::Seconds(t) => {
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::setting(
                    "budget seconds",
                    t.to_string(),
                    "must be finite and > 0",
                ));
            }
            if simulates {
                let pilot = pilot_seconds_per_simulation(simulator, settings.seed_or_default())?;
                per_simulation = Some(pilot);
                let per_simulation = pilot;
                let held_out = settings.calibration + settings.validation;
                let cost = |records: usize| held_out_seconds(per_simulation, records);
                let mut reserve = cost(held_out);
                if reserve > 0.5 * t {
                    // Fewer held-out records rather than a refused budget:
                    // as many as half the budget affords, each set shrunk
                    // alike, never below MIN_HELD_OUT (or what was asked).
                    let fits = ((0.5 * t - 1.0) / (1.2 * per_simulation)).max(0.0);
                    let share = fits / held_out.max(1) as f64;
                    let shrink = |asked: usize| {
                        ((asked as f64 * share) as usize).max(asked.min(MIN_HELD_OUT))
                    };
                    let (calibration, validation) =
                        (shrink(settings.calibration), shrink(settings.validation));
                    reserve = cost(calibration + validation);
                    if reserve > 0.5 * t {
                        return Err(Error::setting(
                            "budget seconds",
                            format!("{t}"),
                            format!(
                                "even {calibration} calibration and {validation} validation \
                                 records take about {reserve:.0} s here ({:.2} ms a simulation, \
                                 measured): give at least {:.0} s",
                                1e3 * per_simulation,
                                (2.0 * reserve).ceil()
                            ),
                        ));
                    }
                    held_out_sizes = Some((calibration, validation));
                }
                let search = (t - reserve - certificate_seconds(budget, settings)).max(0.0);
                let affordable =
                    (0.2 * search / per_simulation).min(SIMULATIONS_PER_BUDGET_SECOND * search);
                (
                    (affordable as usize).max(500).min(memory_cap),
                    Some(start + Duration::from_secs_f64(search)),
                )
            } else {
                // The fits, not the records, cost the time: a chart gives
                // the search as many records as a simulated search of this
                // budget would chart. The held-out records are compressed
                // once by the winner: a small share of the budget, which
                // the final fit measures and uses the rest of.
                let records = (SIMULATIONS_PER_BUDGET_SECOND * t) as usize;
                (
                    records.max(MIN_SEARCH_RECORDS),
                    Some(start + Duration::from_secs_f64(0.95 * t)),
                )
            }
        }
    };
    if !simulates {
        return Ok(ChartSize {
            m: m.min(memory_cap),
            deadline,
            per_simulation: None,
            held_out: None,
        });
    }
    if m < 50 || m > memory_cap {
        return Err(Error::setting(
            "budget simulations",
            m.to_string(),
            format!("must lie in 50..={memory_cap} (the records are kept in memory)"),
        ));
    }
    Ok(ChartSize {
        m,
        deadline,
        per_simulation,
        held_out: held_out_sizes,
    })
}

/// What a budget gives a search.
struct ChartSize {
    /// Training records.
    m: usize,
    deadline: Option<Instant>,
    /// The pilot's wall seconds per simulation, where it ran.
    per_simulation: Option<f64>,
    /// Calibration and validation records, where a time budget could not
    /// afford those asked for.
    held_out: Option<(usize, usize)>,
}

/// The fewest calibration or validation records a time budget shrinks
/// them to: the adaptive intervals need 100, and a certificate on fewer
/// says little.
const MIN_HELD_OUT: usize = 100;

/// Where a search's training records come from, for its chart size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sizing {
    /// Simulated as the run goes: as many as the budget affords.
    Simulated,
    /// Read from a chart or shards: the first of them.
    Read,
}

/// Streams of the timing pilot, apart from the training chart's.
const PILOT_SEED: u64 = 0x0050_494c_4f54; // "PILOT"

/// Parallel throughput of `simulator` in wall seconds per simulation, from
/// a small timed pilot.
fn pilot_seconds_per_simulation<S: Simulator + ?Sized>(simulator: &S, seed: u64) -> Result<f64> {
    let pilot = PILOT_SIMULATIONS;
    let design = simulator.prior().design(pilot, seed ^ PILOT_SEED)?;
    let start = Instant::now();
    simulate_records(simulator, &design, pilot, 0.0, None)?;
    Ok((start.elapsed().as_secs_f64() / pilot as f64).max(1e-9))
}

/// Simulations the pilot times.
const PILOT_SIMULATIONS: usize = 64;

/// Training records a search needs at least: a fifth of them score the
/// candidates.
pub(crate) const MIN_SEARCH_RECORDS: usize = 50;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_search_keeps_what_the_held_out_records_cost_at_the_charts_pace() {
        // 3300 simulations in 7.26 s: 2.2 ms each; 3000 held-out records
        // then take 1.2 x 2.2 ms x 3000 + 1 s = 8.92 s of the 60.
        let (per_simulation, search) =
            search_seconds_measured(Budget::Seconds(60.0), (3300, 7.26), 3000).unwrap();
        assert!((per_simulation - 0.0022).abs() < 1e-12, "{per_simulation}");
        assert!((search - (60.0 - 8.92)).abs() < 1e-9, "{search}");
        // Slower than the budget: no time for the search, not a negative one.
        let (_, none_left) =
            search_seconds_measured(Budget::Seconds(5.0), (3300, 7.26), 3000).unwrap();
        assert!(none_left.abs() < f64::MIN_POSITIVE, "{none_left}");
        // Fewer simulations than the pilot's say less than it did; a
        // simulation budget has no deadline to move.
        assert_eq!(
            search_seconds_measured(Budget::Seconds(60.0), (PILOT_SIMULATIONS - 1, 0.1), 3000),
            None
        );
        assert_eq!(
            search_seconds_measured(Budget::Simulations(3300), (3300, 7.26), 3000),
            None
        );
    }
}
