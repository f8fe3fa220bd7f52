//! Finite differences of a problem's residuals, central and forward: the
//! points they need and the Gauss-Newton products from the residuals
//! there, apart, so that the points of many runs can be evaluated
//! together.

use super::normal_products;

/// The central differences at one point: which points to evaluate, and
/// the steps actually taken (shifted inward at a domain's faces).
///
/// ```
/// use twostage_fit::CentralDifferences;
/// // r(x) = (x0^2, x0 x1) at (1, 2): J = [[2, 0], [2, 1]].
/// let x = [1.0, 2.0];
/// let (differences, points) = CentralDifferences::at(&x, None);
/// let values: Vec<Vec<f64>> = points.iter().map(|p| vec![p[0] * p[0], p[0] * p[1]]).collect();
/// let r = [1.0, 2.0];
/// let (mut jtj, mut jtr) = ([0.0; 4], [0.0; 2]);
/// differences.products(&values, &r, &mut jtj, &mut jtr);
/// // J'J = [[8, 2], [2, 1]], J'r = [2 + 4, 2].
/// for (got, want) in jtj.iter().zip([8.0, 2.0, 2.0, 1.0]) {
///     assert!((got - want).abs() < 1e-6);
/// }
/// assert!((jtr[0] - 6.0).abs() < 1e-6 && (jtr[1] - 2.0).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CentralDifferences {
    /// Per parameter, the distance between its two points.
    widths: Vec<f64>,
}

impl CentralDifferences {
    /// The differences at `x` with steps `1e-6 max(1, |x_j|)`, kept inside
    /// `domain` (lower and upper bounds) where there is one: the points
    /// `x + h_j e_j, x - h_j e_j` for each parameter in order.
    pub fn at(x: &[f64], domain: Option<(&[f64], &[f64])>) -> (Self, Vec<Vec<f64>>) {
        let mut points = Vec::with_capacity(2 * x.len());
        let mut widths = Vec::with_capacity(x.len());
        for j in 0..x.len() {
            let h = 1e-6 * x[j].abs().max(1.0);
            let (mut up, mut down) = (x[j] + h, x[j] - h);
            if let Some((lower, upper)) = domain {
                up = up.min(upper[j]);
                down = down.max(lower[j]);
            }
            for value in [up, down] {
                let mut point = x.to_vec();
                point[j] = value;
                points.push(point);
            }
            widths.push(up - down);
        }
        (Self { widths }, points)
    }

    /// `J'J` and `J'r` from the residuals at the points of [`Self::at`]
    /// (in their order) and those at `x`, `r`.
    pub fn products(&self, values: &[Vec<f64>], r: &[f64], jtj: &mut [f64], jtr: &mut [f64]) {
        let columns = self.jacobian(values, r.len());
        normal_products(&columns, r, jtj, jtr);
    }

    /// The Jacobian's columns (each `rows` long, one after another) from
    /// the residuals at the points of [`Self::at`].
    pub fn jacobian(&self, values: &[Vec<f64>], rows: usize) -> Vec<f64> {
        let rows = rows.max(1);
        let mut columns = vec![0.0; self.widths.len() * rows];
        for (j, column) in columns.chunks_exact_mut(rows).enumerate() {
            let (plus, minus) = (&values[2 * j], &values[2 * j + 1]);
            for ((c, p), m) in column.iter_mut().zip(plus).zip(minus) {
                *c = (p - m) / self.widths[j];
            }
        }
        columns
    }
}

/// Forward differences at one point: `q` points instead of the central
/// differences' `2q`, from the residuals at the point itself, which a
/// descent has already; less accurate (first order in the step), which a
/// descent's steps tolerate and an interval's curvature does not.
///
/// ```
/// use twostage_fit::ForwardDifferences;
/// // r(x) = (x0^2, x0 x1) at (1, 2): J = [[2, 0], [2, 1]].
/// let x = [1.0, 2.0];
/// let (differences, points) = ForwardDifferences::at(&x, None);
/// assert_eq!(points.len(), 2);
/// let values: Vec<Vec<f64>> = points.iter().map(|p| vec![p[0] * p[0], p[0] * p[1]]).collect();
/// let r = [1.0, 2.0];
/// let (mut jtj, mut jtr) = ([0.0; 4], [0.0; 2]);
/// differences.products(&values, &r, &mut jtj, &mut jtr);
/// for (got, want) in jtj.iter().zip([8.0, 2.0, 2.0, 1.0]) {
///     assert!((got - want).abs() < 1e-5);
/// }
/// assert!((jtr[0] - 6.0).abs() < 1e-5 && (jtr[1] - 2.0).abs() < 1e-5);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ForwardDifferences {
    /// Per parameter, the signed step from the point to its neighbour.
    steps: Vec<f64>,
}

impl ForwardDifferences {
    /// The differences at `x` with steps `1e-6 max(1, |x_j|)`, taken
    /// backward where a step forward would leave `domain`: the points `x +
    /// h_j e_j` for each parameter in order.
    pub fn at(x: &[f64], domain: Option<(&[f64], &[f64])>) -> (Self, Vec<Vec<f64>>) {
        let mut points = Vec::with_capacity(x.len());
        let mut steps = Vec::with_capacity(x.len());
        for j in 0..x.len() {
            let h = 1e-6 * x[j].abs().max(1.0);
            let mut value = x[j] + h;
            if let Some((lower, upper)) = domain
                && value > upper[j]
            {
                value = (x[j] - h).max(lower[j]);
            }
            let mut point = x.to_vec();
            point[j] = value;
            points.push(point);
            steps.push(value - x[j]);
        }
        (Self { steps }, points)
    }

    /// `J'J` and `J'r` from the residuals at the points of [`Self::at`]
    /// (in their order) and those at `x`, `r`.
    pub fn products(&self, values: &[Vec<f64>], r: &[f64], jtj: &mut [f64], jtr: &mut [f64]) {
        let rows = r.len().max(1);
        let mut columns = vec![0.0; self.steps.len() * rows];
        for (j, column) in columns.chunks_exact_mut(rows).enumerate() {
            let step = self.steps[j];
            for ((c, p), base) in column.iter_mut().zip(&values[j]).zip(r) {
                // A step of zero (a domain narrower than it): no slope seen.
                *c = if step == 0.0 { 0.0 } else { (p - base) / step };
            }
        }
        normal_products(&columns, r, jtj, jtr);
    }
}
