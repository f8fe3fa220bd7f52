//! Progress bars for training runs: one indicatif bar per stage on stderr,
//! hidden when stderr is not a terminal (indicatif checks) or on --quiet.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use twostage::{Progress, Stage};

/// Draws the stages of [`twostage::TwoStage::train`], and times them.
pub struct Bars {
    current: Mutex<Option<ProgressBar>>,
    quiet: bool,
    /// When the running stage began, and each stage's wall time so far
    /// (in `Stage` order; a stage may run more than once, as in --auto).
    clock: Mutex<(Option<Instant>, [Duration; 4])>,
}

impl Bars {
    /// Bars on stderr, or none at all when `quiet`.
    pub fn new(quiet: bool) -> Self {
        Self {
            current: Mutex::new(None),
            quiet,
            clock: Mutex::new((None, [Duration::ZERO; 4])),
        }
    }

    /// The wall time of each stage that ran, as "simulate + compress
    /// 1.200 s, fit 3.400 s, ...".
    pub fn phase_times(&self) -> String {
        let clock = self
            .clock
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        STAGES
            .iter()
            .zip(clock.1)
            .filter(|(_, time)| !time.is_zero())
            .map(|(stage, time)| format!("{} {:.3} s", phase(*stage), time.as_secs_f64()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn tick(&self, stage: Stage, starting: bool) {
        let mut clock = self
            .clock
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if starting {
            clock.0 = Some(Instant::now());
        } else if let Some(began) = clock.0.take() {
            clock.1[slot(stage)] += began.elapsed();
        }
    }

    fn with_bar(&self, f: impl FnOnce(&mut Option<ProgressBar>)) {
        // A poisoned lock only means another thread panicked mid-draw: the
        // bar is cosmetic, keep going with whatever it holds.
        let mut guard = self
            .current
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(&mut guard);
    }
}

const STAGES: [Stage; 4] = [
    Stage::Training,
    Stage::Fitting,
    Stage::Calibration,
    Stage::Validation,
];

fn slot(stage: Stage) -> usize {
    STAGES.iter().position(|s| *s == stage).unwrap_or(0)
}

/// The phase's name in the timing line: the training chart is simulated
/// and compressed record by record (so memory stays bounded), one phase.
fn phase(stage: Stage) -> &'static str {
    match stage {
        Stage::Training => "simulate + compress",
        Stage::Fitting => "fit",
        Stage::Calibration => "calibrate",
        Stage::Validation => "validate",
    }
}

fn what(stage: Stage) -> &'static str {
    match stage {
        Stage::Training => "simulating + compressing",
        Stage::Fitting => "fitting stage 2",
        Stage::Calibration => "calibrating intervals",
        Stage::Validation => "validating",
    }
}

impl Progress for Bars {
    fn begin(&self, stage: Stage, total: usize) {
        let bar = if self.quiet {
            ProgressBar::hidden()
        } else if total == 0 {
            let spinner = ProgressBar::new_spinner().with_style(
                ProgressStyle::with_template("  {spinner} {msg:<22} {elapsed}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            spinner.enable_steady_tick(Duration::from_millis(120));
            spinner
        } else {
            ProgressBar::new(total as u64).with_style(
                ProgressStyle::with_template(
                    "  {msg:<24} {bar:20} {pos}/{len} sims, {elapsed} (eta {eta})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            )
        };
        bar.set_message(what(stage));
        self.with_bar(|current| *current = Some(bar));
        self.tick(stage, true);
    }

    fn advance(&self, _stage: Stage, done: usize) {
        self.with_bar(|current| {
            if let Some(bar) = current {
                bar.inc(done as u64);
            }
        });
    }

    fn end(&self, stage: Stage) {
        self.tick(stage, false);
        self.with_bar(|current| {
            if let Some(bar) = current.take() {
                bar.finish();
            }
        });
    }

    fn note(&self, message: &str) {
        if !self.quiet {
            eprintln!("{message}");
        }
    }
}
