//! Element-wise maps of the estimate path: standardization and the clip to
//! the prior box. The trained values (means, scales, bounds) are any
//! [`Values`]: a slice, or an exported estimator's bytes read in place.

use crate::Values;

/// `z = (x - mean) / scale`, element by element (over the shortest slice).
///
/// ```
/// let mut z = [0.0; 2];
/// twostage_kernels::vector::standardize(&[3.0, -1.0], &[1.0, 1.0][..], &[2.0, 4.0][..], &mut z);
/// assert_eq!(z, [1.0, -0.5]);
/// ```
#[inline]
pub fn standardize<M, S>(x: &[f64], mean: &M, scale: &S, z: &mut [f64])
where
    M: Values + ?Sized,
    S: Values + ?Sized,
{
    let n = mean.len().min(scale.len());
    for (i, (zi, xi)) in z.iter_mut().zip(x).enumerate().take(n) {
        *zi = (xi - mean.at(i)) / scale.at(i);
    }
}

/// `x = mean + scale z`, in place: the inverse of [`standardize`].
#[inline]
pub fn unstandardize_in_place<M, S>(z: &mut [f64], mean: &M, scale: &S)
where
    M: Values + ?Sized,
    S: Values + ?Sized,
{
    let n = mean.len().min(scale.len());
    for (i, zi) in z.iter_mut().enumerate().take(n) {
        *zi = mean.at(i) + scale.at(i) * *zi;
    }
}

/// Clip each component to `[lower, upper]`; a NaN (a network that
/// diverged) becomes the interval's centre, since clamping would keep it.
///
/// ```
/// let mut theta = [-2.0, f64::NAN, 0.3];
/// twostage_kernels::vector::clip_to_box(&mut theta, &[-1.0; 3][..], &[1.0; 3][..]);
/// assert_eq!(theta, [-1.0, 0.0, 0.3]);
/// ```
#[inline]
pub fn clip_to_box<L, U>(theta: &mut [f64], lower: &L, upper: &U)
where
    L: Values + ?Sized,
    U: Values + ?Sized,
{
    let n = lower.len().min(upper.len());
    for (i, t) in theta.iter_mut().enumerate().take(n) {
        let (lo, hi) = (lower.at(i), upper.at(i));
        // As f64::clamp, without its panic on a box with lower > upper
        // (which would also bring float formatting into a firmware).
        *t = if t.is_nan() {
            0.5 * (lo + hi)
        } else if *t < lo {
            lo
        } else if *t > hi {
            hi
        } else {
            *t
        };
    }
}

/// The interval `theta +- half_widths` kept inside the prior's box, into
/// `low` and `high`: a parameter cannot leave its prior's support, and
/// neither does its interval (what is cut off held no probability). A
/// NaN half-width (no interval) gives NaN bounds. Over the shortest of
/// the slices and the box.
///
/// ```
/// let (mut low, mut high) = ([0.0; 2], [0.0; 2]);
/// twostage_kernels::vector::interval_in_box(
///     &[0.1, 2.0], &[0.3, 0.5], &[0.0, 1.0][..], &[5.0, 2.2][..], &mut low, &mut high,
/// );
/// assert_eq!((low, high), ([0.0, 1.5], [0.4, 2.2]));
/// ```
#[inline]
pub fn interval_in_box<L, U>(
    theta: &[f64],
    half_widths: &[f64],
    lower: &L,
    upper: &U,
    low: &mut [f64],
    high: &mut [f64],
) where
    L: Values + ?Sized,
    U: Values + ?Sized,
{
    let n = lower.len().min(upper.len());
    let bounds = low.iter_mut().zip(high.iter_mut());
    for (i, ((l, h), (t, w))) in bounds
        .zip(theta.iter().zip(half_widths))
        .enumerate()
        .take(n)
    {
        if w.is_nan() {
            // `max` would take the box's bound for a missing interval.
            (*l, *h) = (f64::NAN, f64::NAN);
        } else {
            (*l, *h) = ((t - w).max(lower.at(i)), (t + w).min(upper.at(i)));
        }
    }
}
