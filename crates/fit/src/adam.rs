//! Adam (Kingma and Ba 2015): a step along the gradient scaled per weight
//! by running estimates of its first two moments, bias-corrected.

/// The moments of one Adam run over a flat vector of weights.
pub(crate) struct Adam {
    first: Vec<f64>,
    second: Vec<f64>,
    steps: i32,
    learning_rate: f64,
}

impl Adam {
    const BETA1: f64 = 0.9;
    const BETA2: f64 = 0.999;
    const EPSILON: f64 = 1e-8;

    /// A run over `n` weights at `learning_rate`, no step taken.
    pub(crate) fn new(n: usize, learning_rate: f64) -> Self {
        Self {
            first: vec![0.0; n],
            second: vec![0.0; n],
            steps: 0,
            learning_rate,
        }
    }

    /// Move `params` one step against `gradient`.
    pub(crate) fn step(&mut self, params: &mut [f64], gradient: &[f64]) {
        self.steps = self.steps.saturating_add(1);
        let (c1, c2) = (
            1.0 - Self::BETA1.powi(self.steps),
            1.0 - Self::BETA2.powi(self.steps),
        );
        for ((p, g), (m, v)) in params
            .iter_mut()
            .zip(gradient)
            .zip(self.first.iter_mut().zip(self.second.iter_mut()))
        {
            *m = Self::BETA1 * *m + (1.0 - Self::BETA1) * g;
            *v = Self::BETA2 * *v + (1.0 - Self::BETA2) * g * g;
            *p -= self.learning_rate * (*m / c1) / ((*v / c2).sqrt() + Self::EPSILON);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Adam;

    /// The first step of Adam moves every weight by the learning rate
    /// against its gradient's sign (m / c1 = g, v / c2 = g^2), whatever the
    /// gradient's size; on a quadratic it comes to the minimum.
    #[test]
    fn the_first_step_is_the_learning_rate_and_a_bowl_is_descended() {
        let mut adam = Adam::new(3, 0.1);
        let mut p = [1.0, -2.0, 0.5];
        adam.step(&mut p, &[4.0, -1e-3, 0.0]);
        assert!(
            (p[0] - 0.9).abs() < 1e-9
                && (p[1] + 1.9).abs() < 1e-6
                && p[2].to_bits() == 0.5f64.to_bits()
        );
        let mut adam = Adam::new(2, 0.05);
        let mut q = [3.0, -1.0];
        for _ in 0..2000 {
            let g = [2.0 * (q[0] - 1.0), 20.0 * (q[1] + 0.5)];
            adam.step(&mut q, &g);
        }
        assert!(
            (q[0] - 1.0).abs() < 1e-3 && (q[1] + 0.5).abs() < 1e-3,
            "{q:?}"
        );
    }
}
