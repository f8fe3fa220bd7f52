//! The two-stage estimator f = clip(h(g(u, y))) once it is trained: its
//! estimate, its intervals (conformal and feature-adaptive), its
//! out-of-distribution flag, its file format and its export to the
//! embedded runtime. Training builds one from its fitted stages
//! ([`Estimator::from_stages`]), calibrates it and validates it on
//! held-out records ([`Estimator::calibrate`], [`Estimator::validate`]);
//! everything else here only reads it.
//!
//! Users reach these names through the `twostage` facade, which is why the
//! examples train through it.
#![deny(missing_docs)]

mod adaptive;
mod assessment;
mod decoded;
mod envelope;
mod error;
mod estimator;
mod file;
mod held;
mod layout;
mod posterior;
mod runtime_export;
pub mod space;
mod stored;

pub use adaptive::AdaptiveIntervals;
pub use envelope::{ENVELOPE_LEVEL, FeatureEnvelope};
pub use error::{Error, FileError, InvalidSetting, Result};
pub use estimator::{
    Assessment, EstimateWorkspace, Estimator, RecordShape, SignalNames, TrainingInfo,
    interval_in_box,
};
pub use file::{FORMAT_VERSION, MAGIC, check_writable, write_whole};
