//! FMUs as simulators for the two-stage estimator.
//!
//! The paper's car was a Modelica model simulated from Matlab; today such
//! models travel as FMUs (Functional Mock-up Interface 2.0 and 3.0). This
//! crate runs one behind the [`Simulator`](twostage_models::Simulator)
//! trait, so that charts, training and validation take an FMU as they take
//! a built-in model:
//!
//! - [`Fmu::open`] unpacks an archive and reads `modelDescription.xml`
//!   ([`ModelDescription`]);
//! - [`FmuSimulator`] loads the binary for this platform, sets the
//!   parameters to estimate before initialization, drives the inputs from
//!   the input design (held between samples) and noise inputs from the
//!   experiment's stream, and reads the outputs at every sample, by
//!   co-simulation (`doStep`, the FMU's own solver) or model exchange (the
//!   project's RK4, refusing FMUs with state events);
//! - every failure is an [`FmiError`] naming the FMU, the variable or the
//!   call, and quoting what the FMU logged.
//!
//! docs/fmu.md walks from an FMU to a validated estimator.
//!
//! # Example
//!
//! ```no_run
//! use twostage_fmi::FmuSimulator;
//! use twostage_models::{experiment_rng, InputSignal, ModelSpec, Prior, Simulator};
//!
//! let spec = ModelSpec::new("mass-spring", &["k", "c"],
//!     Prior::uniform_box(&[1.0, 0.1], &[4.0, 1.0])?, 0.01, 1000)?
//!     .with_signals(&["force"], &["position"]);
//! let fmu = FmuSimulator::builder("MassSpring.fmu", spec)
//!     .input(InputSignal::white_gaussian(1.0)?)
//!     .noise_input("disturbance", 0.1)
//!     .build()?;
//! let mut record = fmu.spec().new_record();
//! fmu.simulate(&[2.0, 0.5], &mut experiment_rng(7, 0), &mut record)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod archive;
mod description;
mod error;
mod ffi;
mod run;
mod setup;
mod simulator;
mod worker;

pub use archive::platform_folder;
pub use description::{
    Causality, DefaultExperiment, FmiVersion, Interface, InterfaceKind, ModelDescription,
    Variability, Variable,
};
pub use error::{FmiError, Result};
pub use simulator::{Execution, Fmu, FmuSimulator, FmuSimulatorBuilder};
pub use worker::{serve_worker, serve_workers_from_this_program};
