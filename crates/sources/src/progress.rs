//! Progress of a training run, for bars, logs or cancellation-free
//! monitoring: the facade calls an observer, the caller decides how to show
//! it (the CLI draws indicatif bars).

/// The stages of a training run, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Simulating and compressing the training chart.
    Training,
    /// Simulating the training records for a stage 1 that learns, and
    /// training its summary network on them.
    Learning,
    /// Fitting stage 2 (no count: it ends when the fit does).
    Fitting,
    /// Simulating the calibration records of the conformal intervals.
    Calibration,
    /// Simulating the validation records of the report.
    Validation,
}

impl Stage {
    /// A short lower-case label, e.g. `"training"`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Training => "training",
            Self::Learning => "learning stage 1",
            Self::Fitting => "fitting",
            Self::Calibration => "calibration",
            Self::Validation => "validation",
        }
    }
}

/// Observer of a training run. Every method has an empty default, so an
/// implementation overrides only what it shows. `advance` is called from
/// the worker threads, once per finished simulation.
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use twostage_models::{Benchmark, Simulator};
/// use twostage_sources::{Progress, Stage, simulate_records};
///
/// #[derive(Default)]
/// struct Count(AtomicUsize);
/// impl Progress for Count {
///     fn advance(&self, _stage: Stage, done: usize) {
///         self.0.fetch_add(done, Ordering::Relaxed);
///     }
/// }
///
/// let model = Benchmark::builder().n_samples(200).build()?;
/// let design = model.prior().design(100, 1)?;
/// let count = Count::default();
/// simulate_records(&model, &design, 100, 0.0, Some((Stage::Training, &count)))?;
/// assert_eq!(count.0.load(Ordering::Relaxed), 100);
/// # Ok::<(), twostage_sources::Error>(())
/// ```
pub trait Progress: Sync {
    /// A stage starts with `total` steps (0: unknown, as for fitting).
    fn begin(&self, stage: Stage, total: usize) {
        let _ = (stage, total);
    }
    /// `done` more steps of `stage` finished.
    fn advance(&self, stage: Stage, done: usize) {
        let _ = (stage, done);
    }
    /// The stage finished (successfully or not).
    fn end(&self, stage: Stage) {
        let _ = stage;
    }
    /// A one-line message for the person watching, such as what the run
    /// found in its records ("merging 4 shards: ...").
    fn note(&self, message: &str) {
        let _ = message;
    }
    /// What a long stage is doing now, replacing the last status (the
    /// automatic design: its round, candidate and budget); shown on the
    /// bar, or repeated by a plain log line every few seconds.
    fn status(&self, message: &str) {
        let _ = message;
    }
    /// A step of a run other than training starts: `what` over `total`
    /// `unit`s ("refining", 12, "records"), each finished one reported by
    /// [`Progress::advance_step`], from any thread.
    fn begin_step(&self, what: &'static str, total: usize, unit: &'static str) {
        let _ = (what, total, unit);
    }
    /// `done` more units of the running step finished.
    fn advance_step(&self, done: usize) {
        let _ = done;
    }
    /// The running step ended (successfully or not).
    fn end_step(&self) {}
}

/// The observer that shows nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {}

impl std::fmt::Debug for dyn Progress + '_ {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("dyn Progress")
    }
}
