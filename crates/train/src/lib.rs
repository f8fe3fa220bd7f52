//! Training a two-stage estimator: the [`TwoStage`] builder (what a run is
//! asked for), its [`RunSettings`], and the prepared [`Run`] that fits,
//! calibrates and validates. The automatic design trains through the same
//! run ([`TwoStage::prepare`], [`Run::finish`]).
//!
//! Users reach these names through the `twostage` facade, which is why the
//! examples use it.
#![deny(missing_docs)]

mod builder;
mod error;
mod run;
mod settings;

pub use builder::TwoStage;
pub use error::{Error, Result};
pub use run::{Run, TrainedOn};
pub use settings::{DEFAULT_SEED, RunSettings};
