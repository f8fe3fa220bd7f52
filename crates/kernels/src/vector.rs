//! Element-wise maps of the estimate path: standardization and the clip to
//! the prior box.

/// `z = (x - mean) / scale`, element by element (over the shortest slice).
///
/// ```
/// let mut z = [0.0; 2];
/// twostage_kernels::vector::standardize(&[3.0, -1.0], &[1.0, 1.0], &[2.0, 4.0], &mut z);
/// assert_eq!(z, [1.0, -0.5]);
/// ```
#[inline]
pub fn standardize(x: &[f64], mean: &[f64], scale: &[f64], z: &mut [f64]) {
    for ((zi, xi), (m, s)) in z.iter_mut().zip(x).zip(mean.iter().zip(scale)) {
        *zi = (xi - m) / s;
    }
}

/// `x = mean + scale z`, in place: the inverse of [`standardize`].
#[inline]
pub fn unstandardize_in_place(z: &mut [f64], mean: &[f64], scale: &[f64]) {
    for (zi, (m, s)) in z.iter_mut().zip(mean.iter().zip(scale)) {
        *zi = m + s * *zi;
    }
}

/// Clip each component to `[lower, upper]`; a NaN (a network that
/// diverged) becomes the interval's centre, since clamping would keep it.
///
/// ```
/// let mut theta = [-2.0, f64::NAN, 0.3];
/// twostage_kernels::vector::clip_to_box(&mut theta, &[-1.0; 3], &[1.0; 3]);
/// assert_eq!(theta, [-1.0, 0.0, 0.3]);
/// ```
#[inline]
pub fn clip_to_box(theta: &mut [f64], lower: &[f64], upper: &[f64]) {
    for (t, (lo, hi)) in theta.iter_mut().zip(lower.iter().zip(upper)) {
        *t = if t.is_nan() {
            0.5 * (lo + hi)
        } else {
            t.clamp(*lo, *hi)
        };
    }
}
