//! Progress bars for training runs: one indicatif bar per stage on stderr,
//! hidden when stderr is not a terminal (indicatif checks) or on --quiet.

use std::sync::Mutex;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};
use twostage::{Progress, Stage};

/// Draws the stages of [`twostage::TwoStage::train`].
pub struct Bars {
    current: Mutex<Option<ProgressBar>>,
    quiet: bool,
}

impl Bars {
    /// Bars on stderr, or none at all when `quiet`.
    pub fn new(quiet: bool) -> Self {
        Self {
            current: Mutex::new(None),
            quiet,
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
    }

    fn advance(&self, _stage: Stage, done: usize) {
        self.with_bar(|current| {
            if let Some(bar) = current {
                bar.inc(done as u64);
            }
        });
    }

    fn end(&self, _stage: Stage) {
        self.with_bar(|current| {
            if let Some(bar) = current.take() {
                bar.finish();
            }
        });
    }
}
