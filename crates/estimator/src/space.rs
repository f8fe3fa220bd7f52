//! The space the stage-2 map learns in: each parameter through its prior's
//! [`Transform`] (the logarithm of a log-normal parameter, the parameter
//! itself otherwise), so that every network output maps back into the
//! prior's support.

use ndarray::{Array2, ArrayView2};
use twostage_kernels::vector::clip_to_box;
use twostage_models::{Marginal, Transform};

/// The training parameters in the learning space (a copy; the identity
/// columns are copied as they are).
///
/// ```
/// use ndarray::array;
/// use twostage::estimator::space::to_learning_space;
/// use twostage::models::Marginal;
///
/// let marginals = [
///     Marginal::Uniform { low: 0.0, high: 1.0 },
///     Marginal::LogNormal { mu: 0.0, sigma: 1.0 },
/// ];
/// let learned = to_learning_space(array![[0.5, 1.0]].view(), &marginals);
/// assert_eq!(learned, array![[0.5, 0.0]]);
/// ```
pub fn to_learning_space(thetas: ArrayView2<'_, f64>, marginals: &[Marginal]) -> Array2<f64> {
    let mut out = thetas.to_owned();
    for (mut column, marginal) in out.columns_mut().into_iter().zip(marginals) {
        let transform = marginal.transform();
        if transform != Transform::Identity {
            column.mapv_inplace(|t| transform.forward(t));
        }
    }
    out
}

/// A network output back to a parameter vector: out of the learning space,
/// then clipped to the prior's box (a NaN becomes the box's centre).
///
/// ```
/// use twostage::estimator::space::to_estimate;
/// use twostage::models::Marginal;
///
/// let mut theta = [2.0, f64::NAN];
/// let uniform = Marginal::Uniform { low: 0.0, high: 1.0 };
/// to_estimate(&mut theta, &[uniform, uniform], &[0.0, 0.0], &[1.0, 4.0]);
/// assert_eq!(theta, [1.0, 2.0]);
/// ```
#[inline]
pub fn to_estimate(theta: &mut [f64], marginals: &[Marginal], lower: &[f64], upper: &[f64]) {
    for (t, marginal) in theta.iter_mut().zip(marginals) {
        *t = marginal.transform().inverse(*t);
    }
    clip_to_box(theta, lower, upper);
}

/// [`to_estimate`] for every row of a matrix of network outputs (rows made
/// contiguous first if they are not; `predict` already returns them so).
///
/// ```
/// use ndarray::array;
/// use twostage::estimator::space::rows_to_estimates;
/// use twostage::models::Marginal;
///
/// let mut rows = array![[-3.0], [0.5]];
/// rows_to_estimates(&mut rows, &[Marginal::Uniform { low: 0.0, high: 1.0 }], &[0.0], &[1.0]);
/// assert_eq!(rows, array![[0.0], [0.5]]);
/// ```
pub fn rows_to_estimates(
    estimates: &mut Array2<f64>,
    marginals: &[Marginal],
    lower: &[f64],
    upper: &[f64],
) {
    if !estimates.is_standard_layout() {
        *estimates = estimates.as_standard_layout().into_owned();
    }
    for mut row in estimates.rows_mut() {
        if let Some(theta) = row.as_slice_mut() {
            to_estimate(theta, marginals, lower, upper);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_normal_parameter_is_learned_in_logs_and_comes_back_positive() {
        let marginals = [
            Marginal::LogNormal {
                mu: 0.0,
                sigma: 1.0,
            },
            Marginal::Uniform {
                low: -1.0,
                high: 1.0,
            },
        ];
        let thetas = ndarray::array![[std::f64::consts::E, 0.5], [1.0, -0.25]];
        let z = to_learning_space(thetas.view(), &marginals);
        assert_eq!(z, ndarray::array![[1.0, 0.5], [0.0, -0.25]]);
        // Any network output lands in the box, and so in the support.
        let (lower, upper) = ([0.01, -1.0], [100.0, 1.0]);
        let mut theta = [-50.0, 0.3];
        to_estimate(&mut theta, &marginals, &lower, &upper);
        assert_eq!(theta.map(f64::to_bits), [0.01f64, 0.3].map(f64::to_bits));
        let mut theta = [1.0, f64::NAN];
        to_estimate(&mut theta, &marginals, &lower, &upper);
        assert!((theta[0] - std::f64::consts::E).abs() < 1e-15 && theta[1] == 0.0);
        let mut rows = z.clone();
        rows_to_estimates(&mut rows, &marginals, &lower, &upper);
        assert!((rows[[0, 0]] - std::f64::consts::E).abs() < 1e-15);
        assert_eq!(rows[[1, 1]].to_bits(), (-0.25f64).to_bits());
    }

    /// Rows in either memory order are clipped, NaN to the centre.
    #[test]
    fn rows_in_any_layout_are_clipped() {
        let uniform = [
            Marginal::Uniform {
                low: -1.0,
                high: 1.0,
            },
            Marginal::Uniform {
                low: 2.0,
                high: 3.0,
            },
        ];
        let want: Array2<f64> = ndarray::array![[-1.0, 3.0], [0.5, 2.5], [0.0, 2.5]];
        let standard = ndarray::array![[-5.0, 9.0], [0.5, f64::NAN], [f64::NAN, 2.5]];
        let mut columns_first = standard
            .t()
            .as_standard_layout()
            .into_owned()
            .reversed_axes();
        assert!(!columns_first.is_standard_layout());
        for mut m in [standard, columns_first.clone()] {
            rows_to_estimates(&mut m, &uniform, &[-1.0, 2.0], &[1.0, 3.0]);
            assert!(
                m.iter()
                    .zip(want.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{m}"
            );
        }
        rows_to_estimates(&mut columns_first, &uniform, &[-1.0, 2.0], &[1.0, 3.0]);
        assert!(columns_first.is_standard_layout());
    }
}
