//! Simulators for the two-stage estimator.
//!
//! The two-stage method of Garatti and Bittanti learns an estimator from
//! simulations: this crate provides what is simulated. It holds
//!
//! - the [`Simulator`] trait and the [`ModelSpec`] that describes a model;
//! - [`IoData`], one experiment's input/output record (signals as columns,
//!   so MIMO systems fit);
//! - [`Prior`], the box of parameter values of interest, sampled uniformly,
//!   by Latin hypercube or by Sobol points ([`Sampling`], [`Design`]);
//! - [`InputSignal`]: white Gaussian noise, the chicane, or a fixed signal;
//! - [`Rk4`], a fixed-step classic Runge-Kutta integrator for any [`OdeSystem`];
//! - the paper's two examples: the [`Benchmark`] system of eq. (5) and the
//!   [`PacejkaCar`] of Section 6, exactly as `spec/pacejka-car.md` fixes it;
//! - per-experiment random streams ([`experiment_rng`]): experiment `i` of
//!   seed `s` is the same, bit for bit, whatever the thread count.
//!
//! # Example
//!
//! Simulate a small chart of the benchmark and check that it is reproducible.
//!
//! ```
//! use twostage_models::{experiment_rng, Benchmark, Simulator};
//!
//! let model = Benchmark::new();
//! let design = model.prior().design(4, 2024)?;
//! let mut record = model.spec().new_record();
//! let mut theta = [0.0];
//! let mut first_outputs = Vec::new();
//! for i in 0..design.len() {
//!     design.fill_theta(i, &mut theta)?;
//!     model.simulate(&theta, &mut experiment_rng(2024, i as u64), &mut record)?;
//!     first_outputs.push(record.output(0)[10]);
//! }
//! // Experiment 2 again, alone: the same bits.
//! design.fill_theta(2, &mut theta)?;
//! model.simulate(&theta, &mut experiment_rng(2024, 2), &mut record)?;
//! assert_eq!(record.output(0)[10].to_bits(), first_outputs[2].to_bits());
//! # Ok::<(), twostage_models::SimError>(())
//! ```
#![deny(missing_docs)]

mod ar_noise;
mod benchmark;
mod builtin;
mod butterworth;
mod data;
mod error;
mod external;
mod external_process;
mod fixed;
mod input;
mod input_design;
mod input_family;
mod input_shape;
mod marginal;
mod ode;
mod origin;
mod pacejka;
mod prbs;
mod prior;
mod resources;
mod rng;
mod signals;
mod simulator;
mod sobol;
mod spec;

pub use ar_noise::ArNoise;
pub use benchmark::{
    BENCHMARK_SAMPLES, Benchmark, BenchmarkBuilder, MEASUREMENT_NOISE_VARIANCE,
    PROCESS_NOISE_VARIANCE,
};
pub use builtin::{BuiltinModel, BuiltinOverrides};
pub use butterworth::MAX_FILTER_ORDER;
pub use data::{IoData, RecordShape};
pub use error::{InvalidSetting, Result, SimError};
pub use external::{ExternalJob, ExternalSimulator, PROTOCOL_VERSION, ProtocolAnswer};
pub use fixed::{FixedValue, FixedValues, WithFixed};
pub use input::{InputSignal, MAX_INPUT_NESTING};
pub use input_design::{
    Drawn, Grid, LIKE_BANDS, LIKE_BINS_PER_BAND, Level, MAX_BURSTS, Phases, Spectrum, Taper,
};
pub use input_family::{
    FAMILY_LEAST_WIDTH, FAMILY_MARGIN, InputDeviation, InputFamily, SUMMARY_NAMES,
};
pub use input_shape::{
    InputShapes, SHAPE_LEVEL, SHAPE_SAMPLE, ShapeSample, input_shape_words, record_shape_numbers,
    shape_of,
};
pub use marginal::{
    Marginal, Transform, UNBOUNDED_TAIL, chi_square_quantile, standard_normal_cdf,
    standard_normal_quantile, truncated_standard_mean,
};
pub use ode::{OdeSystem, Rk4};
pub use origin::RecordsOrigin;
pub use pacejka::{
    CHICANE_AMPLITUDE, PACEJKA_NOISE_VARIANCE, PACEJKA_SAMPLE_TIME, PACEJKA_SAMPLES,
    PACEJKA_STEPS_PER_SAMPLE, PacejkaCar, PacejkaCarBuilder, Tire, Vehicle,
};
pub use prbs::MAX_PRBS_ORDER;
pub use prior::{Design, Prior, Sampling, random_permutation};
pub use resources::{available_memory, free_disk, readable_bytes};
pub use rng::{ExperimentRng, StreamPurpose, experiment_rng, stream_rng};
pub use signals::{SignalColumn, generic_signal_names, signal_columns};
pub use simulator::{
    Block, BlockInputs, Capabilities, CarEquations, Conditions, ModelSpec, NoiseFree, Simulator,
    simulate_one_by_one,
};
pub use twostage_kernels::input_shape::SHAPE_LAGS;

/// Simulate experiment `index` of the chart `(design, seed)`: draw its
/// parameter vector into `theta` and its record into `out`.
///
/// This is the one place that ties an experiment to its random streams, so
/// that every tool (the facade's chart, the command line) produces the same
/// experiment `i` for the same seed.
///
/// ```
/// use twostage_models::{run_experiment, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let design = model.prior().design(10, 5)?;
/// let (mut theta, mut record) = ([0.0], model.spec().new_record());
/// run_experiment(&model, &design, 3, &mut theta, &mut record)?;
/// assert!(model.prior().contains(&theta));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
///
/// # Errors
/// An index outside the design, or a failed simulation.
pub fn run_experiment<S: Simulator + ?Sized>(
    simulator: &S,
    design: &Design,
    index: usize,
    theta: &mut [f64],
    out: &mut IoData,
) -> Result<()> {
    design.fill_theta(index, theta)?;
    simulator.simulate(theta, &mut experiment_rng(design.seed(), index as u64), out)
}

/// Run experiments `start..start + outs.len()` of `design` as one block
/// ([`Simulator::simulate_batch`]): their parameter vectors into `thetas`
/// (`q` values each, in order), their records into `outs`, one result each.
/// Experiment i gives the same bits as [`run_experiment`] whatever block it
/// is in.
///
/// ```
/// use twostage_models::{Benchmark, IoData, Simulator, run_experiment, run_experiments};
/// let model = Benchmark::builder().n_samples(50).build()?;
/// let design = model.prior().design(8, 3)?;
/// let (mut thetas, mut outs) = (vec![0.0; 4], vec![IoData::default(); 4]);
/// let results = run_experiments(&model, &design, 4, &mut thetas, &mut outs);
/// assert!(results.iter().all(Result::is_ok));
/// let (mut theta, mut alone) = ([0.0], IoData::default());
/// run_experiment(&model, &design, 6, &mut theta, &mut alone)?;
/// assert_eq!((thetas[2], &outs[2]), (theta[0], &alone));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
pub fn run_experiments<S: Simulator + ?Sized>(
    simulator: &S,
    design: &Design,
    start: usize,
    thetas: &mut [f64],
    outs: &mut [IoData],
) -> Vec<Result<()>> {
    let q = design.prior().dim();
    let count = outs.len();
    if thetas.len() != count * q {
        let e = SimError::InvalidData(format!(
            "{} parameter slots for {count} experiments of {q} parameters",
            thetas.len()
        ));
        return vec![Err(e); count];
    }
    let mut filled: Vec<Result<()>> = thetas
        .chunks_exact_mut(q)
        .enumerate()
        .map(|(k, theta)| design.fill_theta(start + k, theta))
        .collect();
    let mut rngs: Vec<ExperimentRng> = (0..count)
        .map(|k| experiment_rng(design.seed(), (start + k) as u64))
        .collect();
    let views: Vec<&[f64]> = thetas.chunks_exact(q).collect();
    let simulated = simulator.simulate_batch(&views, &mut rngs, outs);
    for (f, s) in filled.iter_mut().zip(simulated) {
        if f.is_ok() {
            *f = s;
        }
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;

    fn is_send_sync<T: Send + Sync>() {}

    #[test]
    fn public_types_are_send_and_sync() {
        is_send_sync::<Benchmark>();
        is_send_sync::<PacejkaCar>();
        is_send_sync::<IoData>();
        is_send_sync::<Prior>();
        is_send_sync::<Design>();
        is_send_sync::<InputSignal>();
        is_send_sync::<SimError>();
        is_send_sync::<Box<dyn Simulator>>();
    }
}
