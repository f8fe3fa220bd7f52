//! Progress of training runs on stderr: one indicatif bar per stage when
//! stderr is a terminal; plain lines when it is not (a notebook, CI, a log
//! file), at least every 10 s while a stage runs, so that a long search is
//! never silent; nothing on --quiet.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use twostage::{Progress, Stage};

/// Where plain lines go: stderr, or a buffer in tests.
type Sink = Arc<Mutex<dyn Write + Send>>;

/// Draws the stages of [`twostage::TwoStage::train`], and times them.
pub struct Bars {
    current: Mutex<Option<ProgressBar>>,
    quiet: bool,
    /// When the running stage began, and each stage's wall time so far
    /// (in `Stage` order; a stage may run more than once, as in --auto).
    clock: Mutex<(Option<Instant>, [Duration; STAGES.len()])>,
    /// The plain-line log, when stderr is not a terminal.
    log: Option<PlainLog>,
}

/// What the plain-line log knows of the run, shared with its ticker.
struct LogState {
    started: Instant,
    sink: Sink,
    /// The running stage's words, its steps done and total (0: unknown),
    /// and what a step is (sims, records).
    stage: Mutex<Option<&'static str>>,
    unit: Mutex<&'static str>,
    done: AtomicUsize,
    total: AtomicUsize,
    status: Mutex<Option<String>>,
    stop: AtomicBool,
}

/// A ticker thread that writes the state every `interval`.
struct PlainLog {
    state: Arc<LogState>,
    ticker: Option<JoinHandle<()>>,
}

fn lock<T: ?Sized>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A poisoned lock only means another thread panicked mid-draw: the
    // display is cosmetic, keep going with whatever it holds.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl LogState {
    /// One line: elapsed time, then what runs.
    fn line(&self, what: &str) {
        let elapsed = self.started.elapsed().as_secs_f64();
        let mut sink = lock(&self.sink);
        let _ = writeln!(sink, "[{elapsed:>6.1} s] {what}");
        let _ = sink.flush();
    }

    /// The running stage and status in words.
    fn now(&self) -> Option<String> {
        let stage = (*lock(&self.stage))?;
        let (done, total) = (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        );
        let mut text = if total > 0 {
            format!("{stage}: {done}/{total} {}", *lock(&self.unit))
        } else {
            stage.to_string()
        };
        if let Some(status) = lock(&self.status).as_ref() {
            text = format!("{text}; {status}");
        }
        Some(text)
    }
}

impl PlainLog {
    fn start(sink: Sink, interval: Duration) -> Self {
        let state = Arc::new(LogState {
            started: Instant::now(),
            sink,
            stage: Mutex::new(None),
            unit: Mutex::new("sims"),
            done: AtomicUsize::new(0),
            total: AtomicUsize::new(0),
            status: Mutex::new(None),
            stop: AtomicBool::new(false),
        });
        let shared = Arc::clone(&state);
        let ticker = std::thread::spawn(move || {
            let step = Duration::from_millis(50).min(interval);
            let mut last = Instant::now();
            while !shared.stop.load(Ordering::Relaxed) {
                // Woken early by the drop: a finished command does not wait.
                std::thread::park_timeout(step);
                if shared.stop.load(Ordering::Relaxed) {
                    break;
                }
                if last.elapsed() >= interval {
                    last = Instant::now();
                    if let Some(now) = shared.now() {
                        shared.line(&now);
                    }
                }
            }
        });
        Self {
            state,
            ticker: Some(ticker),
        }
    }
}

impl Drop for PlainLog {
    fn drop(&mut self) {
        self.state.stop.store(true, Ordering::Relaxed);
        if let Some(ticker) = self.ticker.take() {
            ticker.thread().unpark();
            let _ = ticker.join();
        }
    }
}

/// How often a plain log repeats the running stage.
const PLAIN_INTERVAL: Duration = Duration::from_secs(10);

impl Bars {
    /// Bars on stderr (plain lines when it is not a terminal), or nothing
    /// at all when `quiet`.
    pub fn new(quiet: bool) -> Self {
        let log = (!quiet && !std::io::stderr().is_terminal()).then(|| {
            let sink: Sink = Arc::new(Mutex::new(std::io::stderr()));
            PlainLog::start(sink, PLAIN_INTERVAL)
        });
        Self::with_log(quiet, log)
    }

    fn with_log(quiet: bool, log: Option<PlainLog>) -> Self {
        Self {
            current: Mutex::new(None),
            quiet,
            clock: Mutex::new((None, [Duration::ZERO; STAGES.len()])),
            log,
        }
    }

    /// The wall time of each stage that ran, and what the run spent
    /// outside them, summing to `total`: "simulate + compress 1.200 s,
    /// fit 3.400 s, ..., other 0.300 s (...)". `other` names where that
    /// time goes: `outside`.
    pub fn phase_times(&self, total: Duration, outside: &str) -> String {
        let clock = lock(&self.clock);
        let mut parts: Vec<String> = STAGES
            .iter()
            .zip(clock.1)
            .filter(|(_, time)| !time.is_zero())
            .map(|(stage, time)| format!("{} {:.3} s", phase(*stage), time.as_secs_f64()))
            .collect();
        let timed: Duration = clock.1.iter().sum();
        let other = total.saturating_sub(timed);
        parts.push(format!("other {:.3} s ({outside})", other.as_secs_f64()));
        parts.join(", ")
    }

    fn tick(&self, stage: Stage, starting: bool) {
        let mut clock = lock(&self.clock);
        if starting {
            clock.0 = Some(Instant::now());
        } else if let Some(began) = clock.0.take() {
            clock.1[slot(stage)] += began.elapsed();
        }
    }

    fn with_bar(&self, f: impl FnOnce(&mut Option<ProgressBar>)) {
        f(&mut lock(&self.current));
    }
}

const STAGES: [Stage; 5] = [
    Stage::Learning,
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
        Stage::Learning => "learn stage 1",
        Stage::Training => "simulate + compress",
        Stage::Fitting => "fit",
        Stage::Calibration => "calibrate",
        Stage::Validation => "validate",
    }
}

fn what(stage: Stage) -> &'static str {
    match stage {
        Stage::Learning => "learning stage 1",
        Stage::Training => "simulating + compressing",
        Stage::Fitting => "fitting stage 2",
        Stage::Calibration => "calibrating intervals",
        Stage::Validation => "validating",
    }
}

impl Progress for Bars {
    fn begin(&self, stage: Stage, total: usize) {
        let bar = if self.quiet || self.log.is_some() {
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
        if let Some(log) = &self.log {
            let state = &log.state;
            *lock(&state.stage) = Some(what(stage));
            *lock(&state.unit) = "sims";
            *lock(&state.status) = None;
            state.done.store(0, Ordering::Relaxed);
            state.total.store(total, Ordering::Relaxed);
            state.line(&match total {
                0 => what(stage).to_string(),
                n => format!("{}: {n} sims", what(stage)),
            });
        }
    }

    fn advance(&self, _stage: Stage, done: usize) {
        self.with_bar(|current| {
            if let Some(bar) = current {
                bar.inc(done as u64);
            }
        });
        if let Some(log) = &self.log {
            log.state.done.fetch_add(done, Ordering::Relaxed);
        }
    }

    fn end(&self, stage: Stage) {
        self.tick(stage, false);
        self.with_bar(|current| {
            if let Some(bar) = current.take() {
                bar.finish();
            }
        });
        if let Some(log) = &self.log {
            *lock(&log.state.stage) = None;
        }
    }

    fn note(&self, message: &str) {
        if !self.quiet {
            eprintln!("{message}");
        }
    }

    fn status(&self, message: &str) {
        self.with_bar(|current| {
            if let Some(bar) = current {
                bar.set_message(message.to_string());
            }
        });
        if let Some(log) = &self.log {
            *lock(&log.state.status) = Some(message.to_string());
        }
    }

    /// A step of a command other than training (`what`, over `total`
    /// `unit`s: "refining", 12 "records"): a bar on a terminal; without
    /// one, a line every 10 s while it runs and none before, so that a
    /// quick command stays quiet and a long one is never silent.
    fn begin_step(&self, what: &'static str, total: usize, unit: &'static str) {
        let bar = if self.quiet || self.log.is_some() {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(total as u64).with_style(
                ProgressStyle::with_template(&format!(
                    "  {{msg:<24}} {{bar:20}} {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
                ))
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            )
        };
        bar.set_message(what);
        self.with_bar(|current| *current = Some(bar));
        if let Some(log) = &self.log {
            let state = &log.state;
            *lock(&state.stage) = Some(what);
            *lock(&state.unit) = unit;
            *lock(&state.status) = None;
            state.done.store(0, Ordering::Relaxed);
            state.total.store(total, Ordering::Relaxed);
        }
    }

    /// `done` more steps of the running one.
    fn advance_step(&self, done: usize) {
        self.with_bar(|current| {
            if let Some(bar) = current {
                bar.inc(done as u64);
            }
        });
        if let Some(log) = &self.log {
            log.state.done.fetch_add(done, Ordering::Relaxed);
        }
    }

    /// The running step has ended.
    fn end_step(&self) {
        self.with_bar(|current| {
            if let Some(bar) = current.take() {
                bar.finish_and_clear();
            }
        });
        if let Some(log) = &self.log {
            *lock(&log.state.stage) = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without a terminal, a stage that runs for a while is repeated with
    /// its status at every interval, and nothing is written after the end.
    #[test]
    fn a_plain_log_repeats_the_running_stage() {
        let buffer = Arc::new(Mutex::new(Vec::<u8>::new()));
        let sink: Sink = buffer.clone();
        let bars = Bars::with_log(
            false,
            Some(PlainLog::start(sink, Duration::from_millis(100))),
        );
        bars.begin(Stage::Fitting, 0);
        bars.status("round 1: candidate 2 of 9, budget 120 s");
        let status = "fitting stage 2; round 1: candidate 2 of 9, budget 120 s";
        let repeats = || {
            let text = String::from_utf8(lock(&buffer).clone()).unwrap();
            text.lines().filter(|l| l.ends_with(status)).count()
        };
        // However slow the machine: the lines come while the stage runs.
        let waited = Instant::now();
        while repeats() < 3 && waited.elapsed() < Duration::from_secs(20) {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(repeats() >= 3);
        bars.end(Stage::Fitting);
        let written_at_end = lock(&buffer).len();
        std::thread::sleep(Duration::from_millis(300));
        drop(bars);
        let text = String::from_utf8(lock(&buffer).clone()).unwrap();
        let first = text.lines().next().unwrap_or_default();
        assert_eq!(first.split("] ").nth(1), Some("fitting stage 2"), "{text}");
        // Between stages there is nothing to repeat.
        assert_eq!(lock(&buffer).len(), written_at_end, "{text}");
    }

    /// A command's step (not training) is silent at first, then repeats
    /// its records done; its end stops the lines.
    #[test]
    fn a_long_step_is_never_silent_and_a_short_one_says_nothing() {
        let buffer = Arc::new(Mutex::new(Vec::<u8>::new()));
        let sink: Sink = buffer.clone();
        let bars = Bars::with_log(
            false,
            Some(PlainLog::start(sink, Duration::from_millis(100))),
        );
        bars.begin_step("refining", 3, "records");
        assert!(lock(&buffer).is_empty(), "a line before the first interval");
        bars.advance_step(1);
        let text = || String::from_utf8(lock(&buffer).clone()).unwrap();
        let waited = Instant::now();
        while !text().contains("refining: 1/3 records")
            && waited.elapsed() < Duration::from_secs(20)
        {
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(text().contains("] refining: 1/3 records"), "{}", text());
        bars.end_step();
        let at_end = lock(&buffer).len();
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(lock(&buffer).len(), at_end, "{}", text());
    }
}
