//! A trained two-stage estimator where the paper wants it: in a control
//! unit, sample by sample as the data arrives, in a few KiB.
//!
//! `#![no_std]`, no allocation, no panics: every failure is an [`Error`]
//! (with a stable [`Error::code`] for C). An [`Estimator`] views a blob
//! written by `twostage export --to runtime` where it lies (flash, a
//! `static`, a buffer read from a file); a [`Stream`] accumulates stage 1
//! as the samples come, in a workspace the caller owns, and
//! [`Stream::finish`] gives the estimate, its interval half-widths and the
//! out-of-distribution distance.
//!
//! Stage 1 (the ARX least squares of eq. (2)) is kept as its normal
//! equations, sums of lagged products, in double-double arithmetic, and
//! solved in double-double: the host refines ill-conditioned problems
//! (the car's chicane) against the record, which a stream no longer has,
//! and double-double reaches the same answer from the sums alone. The rest
//! (standardization, network, clip, intervals, envelope) runs the host's
//! own kernels ([`twostage_kernels`]) on the blob's bytes, so estimates
//! agree with the host's `Estimator::estimate` to about 1e-12 (docs/embedded.md).
//!
//! A stage 1 that linearizes the car (the host's `linearized`) is
//! streamed too: the car runs with its sensitivities as the samples come,
//! its per-sample state four dual numbers, and its least-squares sums
//! close the record (feature `linearized`, on by default).
//!
//! The layout of the blob is [`format`]'s.
#![no_std]
#![deny(missing_docs)]
#![deny(
    clippy::panic,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::indexing_slicing))]

mod bytes;
mod correlations;
mod dd;
mod draws;
mod error;
mod estimator;
pub mod format;
mod learned;
mod network;
mod posterior;
mod stream;

pub use bytes::LeF64s;
pub use error::Error;
pub use estimator::Estimator;
pub use stream::{Assessment, Intervals, Stream};

impl Estimator<'_> {
    /// Estimate a whole record at once: `inputs` and `outputs` hold the
    /// samples row by row (sample t's inputs are `inputs[t * n_inputs..]`),
    /// pushed through a [`Stream`] over `work`.
    ///
    /// # Errors
    /// [`Error::SignalCount`] when the arrays do not hold the same number
    /// of samples, and those of [`Stream::push`] and [`Stream::finish`].
    pub fn estimate_record(
        &self,
        inputs: &[f64],
        outputs: &[f64],
        work: &mut [f64],
        theta: &mut [f64],
        half_widths: &mut [f64],
    ) -> Result<Assessment, Error> {
        let shape = Error::SignalCount {
            inputs: self.n_inputs(),
            outputs: self.n_outputs(),
        };
        let samples = outputs.len() / self.n_outputs().max(1);
        if samples * self.n_outputs() != outputs.len() || samples * self.n_inputs() != inputs.len()
        {
            return Err(shape);
        }
        let mut stream = Stream::new(self, work)?;
        for t in 0..samples {
            let u = inputs
                .get(t * self.n_inputs()..(t + 1) * self.n_inputs())
                .ok_or(shape)?;
            let y = outputs
                .get(t * self.n_outputs()..(t + 1) * self.n_outputs())
                .ok_or(shape)?;
            stream.push(u, y)?;
        }
        stream.finish(theta, half_widths)
    }
}
