//! Shared set-up of the criterion benchmarks: one configuration, and the
//! recorded experiments every method is measured on.
#![deny(missing_docs)]

use std::time::Duration;

use criterion::Criterion;
use twostage::models::{IoData, Simulator, experiment_rng};

/// The criterion configuration of every group: enough samples for stable
/// medians on a 2-core machine without making a full run take an hour.
pub fn config() -> Criterion {
    Criterion::default()
        .sample_size(50)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4))
}

/// The configuration of slow groups (training), with fewer samples.
pub fn slow_config() -> Criterion {
    Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(20))
}

/// One recorded experiment of `model` at `theta`, the same in every bench.
///
/// # Panics
/// If the simulation fails: the built-in models at the given theta do not.
pub fn record<S: Simulator + ?Sized>(model: &S, theta: &[f64]) -> IoData {
    let mut record = model.spec().new_record();
    model
        .simulate(theta, &mut experiment_rng(20_131_105, 0), &mut record)
        .unwrap_or_else(|e| panic!("bench record at {theta:?}: {e}"));
    record
}
