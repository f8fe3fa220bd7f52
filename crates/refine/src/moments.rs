//! Posterior moments from weighted grid points: what every grid-based
//! posterior (the local posterior that refines a TS estimate here, the car's
//! Bayes reference in the baselines) reduces its grid to.

/// Running sums of weights and of weighted first and second moments, per
/// coordinate, in the order the points are added (so the same points in the
/// same order give the same bits).
///
/// ```
/// use twostage_refine::WeightedMoments;
/// // Weights 1, 3 on 0 and 2: mean 1.5, variance 0.75.
/// let mut moments = WeightedMoments::new(1);
/// moments.add(1.0, &[0.0]);
/// moments.add(3.0, &[2.0]);
/// let (mean, sd) = moments.mean_and_sd();
/// assert_eq!(mean, [1.5]);
/// assert!((sd[0] - 0.75f64.sqrt()).abs() < 1e-15);
/// ```
#[derive(Debug, Clone)]
pub struct WeightedMoments {
    mass: f64,
    first: Vec<f64>,
    second: Vec<f64>,
    /// The weighted products of coordinates a < b, row by row.
    cross: Vec<f64>,
}

impl WeightedMoments {
    /// Empty sums for `q` coordinates.
    pub fn new(q: usize) -> Self {
        Self {
            mass: 0.0,
            first: vec![0.0; q],
            second: vec![0.0; q],
            cross: vec![0.0; q * q.saturating_sub(1) / 2],
        }
    }

    /// Add a point `theta` with weight `w` (an unnormalized posterior value
    /// times its quadrature weight).
    pub fn add(&mut self, w: f64, theta: &[f64]) {
        self.mass += w;
        for ((m1, m2), t) in self.first.iter_mut().zip(&mut self.second).zip(theta) {
            *m1 += w * t;
            *m2 += w * t * t;
        }
        let mut pair = 0;
        for (a, ta) in theta.iter().enumerate() {
            for tb in &theta[a + 1..] {
                self.cross[pair] += w * ta * tb;
                pair += 1;
            }
        }
    }

    /// The posterior mean and standard deviation per coordinate (a negative
    /// variance from rounding counts as zero).
    pub fn mean_and_sd(&self) -> (Vec<f64>, Vec<f64>) {
        let mean: Vec<f64> = self.first.iter().map(|m1| m1 / self.mass).collect();
        let sd = self
            .second
            .iter()
            .zip(&mean)
            .map(|(m2, m)| (m2 / self.mass - m * m).max(0.0).sqrt())
            .collect();
        (mean, sd)
    }

    /// The posterior correlation matrix (row-major q x q; 0 off the
    /// diagonal where a coordinate does not vary).
    ///
    /// ```
    /// use twostage_refine::WeightedMoments;
    /// // Equal weights on (0, 0), (1, 2), (2, 4): perfectly correlated.
    /// let mut moments = WeightedMoments::new(2);
    /// for t in [[0.0, 0.0], [1.0, 2.0], [2.0, 4.0]] {
    ///     moments.add(1.0, &t);
    /// }
    /// let r = moments.correlation();
    /// assert!((r[1] - 1.0).abs() < 1e-12 && r[1] == r[2] && r[0] == 1.0);
    /// ```
    pub fn correlation(&self) -> Vec<f64> {
        let q = self.first.len();
        let (mean, sd) = self.mean_and_sd();
        let mut r = vec![0.0; q * q];
        let mut pair = 0;
        for a in 0..q {
            r[a * q + a] = 1.0;
            for b in a + 1..q {
                let covariance = self.cross[pair] / self.mass - mean[a] * mean[b];
                let scale = sd[a] * sd[b];
                let value = if scale > 0.0 {
                    (covariance / scale).clamp(-1.0, 1.0)
                } else {
                    0.0
                };
                r[a * q + b] = value;
                r[b * q + a] = value;
                pair += 1;
            }
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Weights 1, 2, 1 on 0, 1, 2: mean 1, variance (1 + 0 + 1) / 4.
    #[test]
    fn moments_of_a_small_discrete_distribution() {
        let mut m = WeightedMoments::new(1);
        for (w, t) in [(1.0, 0.0), (2.0, 1.0), (1.0, 2.0)] {
            m.add(w, &[t]);
        }
        let (mean, sd) = m.mean_and_sd();
        assert!((mean[0] - 1.0).abs() < 1e-15 && (sd[0] - 0.5f64.sqrt()).abs() < 1e-15);
    }

    /// The running sums' correlation against a two-pass computation
    /// (centred products) on uneven weights in three coordinates.
    #[test]
    fn correlation_matches_a_two_pass_computation() {
        let points: Vec<(f64, [f64; 3])> = (0..40)
            .map(|i| {
                let x = i as f64 / 7.0;
                (
                    1.0 + (i % 5) as f64,
                    [x.sin(), 0.3 * x + x.cos(), (x * x) % 3.0],
                )
            })
            .collect();
        let mut m = WeightedMoments::new(3);
        for (w, t) in &points {
            m.add(*w, t);
        }
        let mass: f64 = points.iter().map(|p| p.0).sum();
        let mean: Vec<f64> = (0..3)
            .map(|a| points.iter().map(|(w, t)| w * t[a]).sum::<f64>() / mass)
            .collect();
        let cov = |a: usize, b: usize| {
            points
                .iter()
                .map(|(w, t)| w * (t[a] - mean[a]) * (t[b] - mean[b]))
                .sum::<f64>()
                / mass
        };
        let r = m.correlation();
        for a in 0..3 {
            for b in 0..3 {
                let expected = cov(a, b) / (cov(a, a) * cov(b, b)).sqrt();
                assert!((r[a * 3 + b] - expected).abs() < 1e-12, "{a},{b}");
            }
        }
    }
}
