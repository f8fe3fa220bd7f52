//! The arithmetic of the two-stage estimate path, in one place.
//!
//! `#![no_std]` and allocation-free: every routine works on caller-owned
//! slices, so the host library, the C API and a microcontroller run the same
//! code and compute the same numbers. What is here:
//!
//! - [`cholesky`]: the Cholesky factorization with a stated rank tolerance
//!   ([`cholesky::PivotRule`]) and the triangular solves that go with it;
//! - [`lagged`]: the least-squares normal equations of an ARX-type
//!   regression assembled from lagged products of the signals (eq. (2) of
//!   the paper without forming the regressor matrix);
//! - [`layer`]: one dense layer of the network (affine map and activation),
//!   and [`tanh`], its activation, the same bits on every platform;
//! - [`convolution`]: the learned stage 1's strided convolutions and
//!   their pooling over time;
//! - [`vector`]: standardization and clipping to the prior box;
//! - [`mixture`]: a mixture of Gaussians over parameters mapped to the
//!   real line (a density network's head): its log density and draws;
//! - [`random`]: a stream's key, uniforms and standard normals from a
//!   generator's words, the draws' randomness the same on every platform;
//! - [`pacejka`]: the Pacejka car's equations, for plain numbers and for
//!   numbers that carry their derivatives, and [`linearized`], the stage 1
//!   that regresses a record on the car's sensitivities;
//! - [`input_summary`] and [`input_shape`]: what an input was like, and
//!   how far a record's input shape lies from a family's.
//!
//! The summation orders are part of the contract: sums run in index order
//! and pivots are formed by subtracting one product at a time, and the
//! activation is the crate's own [`tanh`], so a caller that changes
//! platforms changes no bit.
//!
//! ```
//! use twostage_kernels::cholesky::{PivotRule, cholesky_in_place, solve_cholesky_in_place};
//! // A = [[4, 2], [2, 3]] = L L' with L = [[2, 0], [1, sqrt(2)]].
//! let mut a = [4.0, 2.0, 2.0, 3.0];
//! cholesky_in_place(&mut a, 2, PivotRule::Positive)?;
//! assert!((a[3] - 2f64.sqrt()).abs() < 1e-15);
//! // A x = (8, 7) has x = (1.25, 1.5).
//! let mut x = [8.0, 7.0];
//! solve_cholesky_in_place(&a, 2, &mut x);
//! assert!((x[0] - 1.25).abs() < 1e-15 && (x[1] - 1.5).abs() < 1e-15);
//! # Ok::<(), twostage_kernels::cholesky::NotPositiveDefinite>(())
//! ```
#![no_std]
#![deny(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

pub mod cholesky;
pub mod convolution;
pub mod input_shape;
pub mod input_summary;
pub mod lagged;
pub mod layer;
pub mod linearized;
pub mod mixture;
pub mod pacejka;
pub mod random;
mod tanh;
pub mod vector;

pub use tanh::tanh;

/// Square root, correctly rounded on every platform (IEEE 754).
#[inline]
pub(crate) fn sqrt(x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        x.sqrt()
    }
    #[cfg(not(feature = "std"))]
    {
        libm::sqrt(x)
    }
}

/// The plain dot product of two slices (over the shorter length), summed
/// in index order from zero.
///
/// ```
/// assert_eq!(twostage_kernels::dot(&[1.0, 2.0, 3.0], &[4.0, 5.0, 6.0]), 32.0);
/// ```
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// A read-only sequence of numbers that the estimate path reads its
/// trained values from: a slice on the host, the little-endian bytes of an
/// exported estimator in place on a microcontroller (which need not be
/// aligned). Reads past the end give NaN, never a panic, so a caller's
/// shape mistake shows in its answer instead of stopping a control unit.
pub trait Values {
    /// How many numbers there are.
    fn len(&self) -> usize;
    /// Whether there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Number `i`, or NaN past the end.
    fn at(&self, i: usize) -> f64;
    /// `sum_c self[offset + c] x[c]` over `c < x.len()`, summed in index
    /// order as [`dot`] does (so every implementation gives the same
    /// bits); NaN when the run passes the end.
    fn dot_from(&self, offset: usize, x: &[f64]) -> f64;
}

impl Values for [f64] {
    #[inline]
    fn len(&self) -> usize {
        <[f64]>::len(self)
    }
    #[inline]
    fn at(&self, i: usize) -> f64 {
        self.get(i).copied().unwrap_or(f64::NAN)
    }
    #[inline]
    fn dot_from(&self, offset: usize, x: &[f64]) -> f64 {
        offset
            .checked_add(x.len())
            .and_then(|end| self.get(offset..end))
            .map_or(f64::NAN, |row| dot(row, x))
    }
}

/// The vector arithmetic that [`lagged`] runs on: a microcontroller uses
/// [`PlainOps`], the host library its SIMD versions. Results may differ in
/// the last bits between implementations (summation order), never within
/// one on one processor.
pub trait VectorOps {
    /// `sum_k a[k] b[k]` over the shorter length.
    fn dot(&self, a: &[f64], b: &[f64]) -> f64;
    /// `r[k] -= x v[k]` for every k of the shorter length.
    fn subtract_scaled(&self, r: &mut [f64], x: f64, v: &[f64]);
}

/// Plain loops in index order: [`dot`], and a scalar update.
///
/// ```
/// use twostage_kernels::{PlainOps, VectorOps};
/// let mut r = [1.0, 2.0];
/// PlainOps.subtract_scaled(&mut r, 2.0, &[0.5, 1.0]);
/// assert_eq!(r, [0.0, 0.0]);
/// assert_eq!(PlainOps.dot(&[1.0, 2.0], &[3.0, 4.0]), 11.0);
/// ```
#[derive(Debug, Clone, Copy, Default)]
pub struct PlainOps;

impl VectorOps for PlainOps {
    #[inline]
    fn dot(&self, a: &[f64], b: &[f64]) -> f64 {
        dot(a, b)
    }
    #[inline]
    fn subtract_scaled(&self, r: &mut [f64], x: f64, v: &[f64]) {
        for (r, v) in r.iter_mut().zip(v) {
            *r -= x * v;
        }
    }
}
