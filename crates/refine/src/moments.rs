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
}

impl WeightedMoments {
    /// Empty sums for `q` coordinates.
    pub fn new(q: usize) -> Self {
        Self {
            mass: 0.0,
            first: vec![0.0; q],
            second: vec![0.0; q],
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
}
