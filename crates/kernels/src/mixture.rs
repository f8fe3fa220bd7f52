//! A conditional density's arithmetic: a mixture of Gaussians with full
//! covariances over the parameters mapped to an unbounded space, as a
//! density network's output layer gives it, and the maps between a
//! parameter's support and that space.
//!
//! Each component is parameterized by the Cholesky factor `U` of its
//! precision (upper triangular, `Σ⁻¹ = U'U`, the diagonal `exp` of free
//! numbers): the log density needs no solve, `log N(z; μ, Σ) = Σ log U_ii
//! − d/2 log 2π − |U (z − μ)|² / 2`, and a draw one back substitution,
//! `z = μ + U⁻¹ ε`. Every function is allocation-free and uses libm's
//! `exp` and `log`, so a host and a microcontroller compute the same bits.
//!
//! The network's outputs of one record (its *head*), for `k` components
//! over `d` parameters, in order: `k` weight logits; `k × d` means,
//! component by component; `k × d` logarithms of `U`'s diagonal; `k ×
//! d(d−1)/2` entries above it, row by row.
//!
//! ```
//! use twostage_kernels::mixture::MixtureShape;
//! // One component in one dimension: the standard normal at 0.
//! let shape = MixtureShape { components: 1, dim: 1 };
//! let head = [0.0, 0.0, 0.0];
//! let log_p = shape.log_density(&head, &[0.0]);
//! assert!((log_p + 0.5 * (2.0 * core::f64::consts::PI).ln()).abs() < 1e-15);
//! ```

use core::f64::consts::PI;

/// How many components over how many parameters: the layout of a head.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MixtureShape {
    /// Components, at least 1.
    pub components: usize,
    /// Parameters, at least 1.
    pub dim: usize,
}

impl MixtureShape {
    /// Entries above the diagonal of one component's factor.
    pub const fn upper_len(self) -> usize {
        self.dim * (self.dim - 1) / 2
    }

    /// The head's length: the network's outputs per record.
    pub const fn outputs(self) -> usize {
        self.components * (1 + 2 * self.dim + self.upper_len())
    }

    /// Where component `c`'s mean starts in the head.
    pub const fn mean_at(self, c: usize) -> usize {
        self.components + c * self.dim
    }

    /// Where component `c`'s log-diagonal starts in the head.
    pub const fn log_diagonal_at(self, c: usize) -> usize {
        self.components * (1 + self.dim) + c * self.dim
    }

    /// Where component `c`'s entries above the diagonal start in the head
    /// (row by row: (0,1), (0,2), ..., (1,2), ...).
    pub const fn upper_at(self, c: usize) -> usize {
        self.components * (1 + 2 * self.dim) + c * self.upper_len()
    }

    /// The place of entry `(i, j)`, `i < j`, among a component's entries
    /// above the diagonal.
    pub const fn upper_index(self, i: usize, j: usize) -> usize {
        i * self.dim - i * (i + 1) / 2 + (j - i - 1)
    }

    /// `log Σ exp(logits)` of the head's weight logits.
    pub fn log_normalizer(self, head: &[f64]) -> f64 {
        log_sum_exp(head[..self.components].iter().copied())
    }

    /// Component `c`'s log density at `z` without its weight: `Σ log U_ii
    /// − d/2 log 2π − |U (z − μ)|² / 2`.
    pub fn component_log_density(self, head: &[f64], c: usize, z: &[f64]) -> f64 {
        let d = self.dim;
        let mean = &head[self.mean_at(c)..self.mean_at(c) + d];
        let log_diagonal = &head[self.log_diagonal_at(c)..self.log_diagonal_at(c) + d];
        let upper = &head[self.upper_at(c)..self.upper_at(c) + self.upper_len()];
        let mut squares = 0.0;
        let mut log_det = 0.0;
        for i in 0..d {
            log_det += log_diagonal[i];
            let mut y = libm::exp(log_diagonal[i]) * (z[i] - mean[i]);
            for j in i + 1..d {
                y += upper[self.upper_index(i, j)] * (z[j] - mean[j]);
            }
            squares += y * y;
        }
        log_det - 0.5 * d as f64 * libm::log(2.0 * PI) - 0.5 * squares
    }

    /// The mixture's log density at `z` (in the unbounded space).
    pub fn log_density(self, head: &[f64], z: &[f64]) -> f64 {
        let normalizer = self.log_normalizer(head);
        log_sum_exp((0..self.components).map(|c| head[c] + self.component_log_density(head, c, z)))
            - normalizer
    }

    /// One draw into `z`: the component whose cumulative weight first
    /// exceeds `uniform` (in `[0, 1)`), then `μ + U⁻¹ ε` for the standard
    /// normal numbers `normals` (`dim` of them).
    pub fn draw(self, head: &[f64], uniform: f64, normals: &[f64], z: &mut [f64]) {
        let c = self.component_at(head, uniform);
        let d = self.dim;
        let mean = &head[self.mean_at(c)..self.mean_at(c) + d];
        let log_diagonal = &head[self.log_diagonal_at(c)..self.log_diagonal_at(c) + d];
        let upper = &head[self.upper_at(c)..self.upper_at(c) + self.upper_len()];
        for i in (0..d).rev() {
            let mut sum = normals[i];
            for j in i + 1..d {
                sum -= upper[self.upper_index(i, j)] * z[j];
            }
            z[i] = sum / libm::exp(log_diagonal[i]);
        }
        for (z, m) in z.iter_mut().zip(mean) {
            *z += m;
        }
    }

    /// One draw into `z` from a generator's `words`: the first word's
    /// uniform chooses the component, the next `2 ⌈dim / 2⌉` give the
    /// standard normals ([`crate::random::standard_normals`], into
    /// `normals`, `dim` long), then [`Self::draw`]. Every draw takes the
    /// same number of words, so draw `k` of a stream starts at a known
    /// word on any platform.
    pub fn draw_from_words(
        self,
        head: &[f64],
        words: &mut impl FnMut() -> u64,
        normals: &mut [f64],
        z: &mut [f64],
    ) {
        let uniform = crate::random::unit_uniform(words());
        crate::random::standard_normals(words, &mut normals[..self.dim]);
        self.draw(head, uniform, normals, z);
    }

    /// Widen every component's spread by `spread` (its logarithm
    /// `log_spread` given too, so that a caller decides once how it is
    /// computed): `U`'s diagonal logarithms lose `log_spread`, the entries
    /// above it are divided by `spread`, so every covariance grows by
    /// `spread²`. A spread of 1 (and 0 for its logarithm) changes no bit.
    pub fn widen(self, head: &mut [f64], spread: f64, log_spread: f64) {
        for c in 0..self.components {
            let at = self.log_diagonal_at(c);
            for v in &mut head[at..at + self.dim] {
                *v -= log_spread;
            }
            let at = self.upper_at(c);
            for v in &mut head[at..at + self.upper_len()] {
                *v /= spread;
            }
        }
    }

    /// The component a draw of `uniform` falls in.
    fn component_at(self, head: &[f64], uniform: f64) -> usize {
        let normalizer = self.log_normalizer(head);
        let mut cumulative = 0.0;
        for (c, logit) in head[..self.components].iter().enumerate() {
            cumulative += libm::exp(logit - normalizer);
            if uniform < cumulative {
                return c;
            }
        }
        // Rounding can leave the weights' sum a hair below 1.
        self.components - 1
    }
}

/// `log Σ exp(x)`, from the largest term so that none overflows; `-inf`
/// for no term or all `-inf`.
pub fn log_sum_exp(x: impl Iterator<Item = f64> + Clone) -> f64 {
    let largest = x.clone().fold(f64::NEG_INFINITY, f64::max);
    if !largest.is_finite() {
        return largest;
    }
    largest + libm::log(x.map(|v| libm::exp(v - largest)).sum::<f64>())
}

/// Where a parameter lives, and so how it is mapped to the whole real
/// line where the mixture lives.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Support {
    /// Any real number: kept as it is.
    Real,
    /// Positive numbers: their logarithm.
    Positive,
    /// `[low, high]`: the logit of the place within it.
    Interval {
        /// Lower bound.
        low: f64,
        /// Upper bound, above `low`.
        high: f64,
    },
}

impl Support {
    /// How close to a bound a value is taken: a value on (or beyond) it
    /// is mapped as if this fraction of the interval (or, for a positive
    /// value, this number) inside, so that a chart with values on its
    /// bounds gives finite numbers.
    pub const EDGE: f64 = 1e-6;

    /// `theta` in the unbounded space.
    ///
    /// ```
    /// use twostage_kernels::mixture::Support;
    /// let unit = Support::Interval { low: 0.0, high: 1.0 };
    /// assert_eq!(unit.to_unbounded(0.5), 0.0);
    /// assert!((unit.from_unbounded(unit.to_unbounded(0.9)) - 0.9).abs() < 1e-15);
    /// // A value on a bound maps to a finite number, and back inside.
    /// assert!(unit.to_unbounded(1.0).is_finite());
    /// ```
    pub fn to_unbounded(self, theta: f64) -> f64 {
        match self {
            Self::Real => theta,
            Self::Positive => libm::log(theta.max(Self::EDGE)),
            Self::Interval { low, high } => {
                let u = within((theta - low) / (high - low), Self::EDGE, 1.0 - Self::EDGE);
                libm::log(u) - libm::log1p(-u)
            }
        }
    }

    /// `z` of the unbounded space as a parameter value: always within the
    /// support (a bound at worst, where rounding takes an extreme `z`).
    pub fn from_unbounded(self, z: f64) -> f64 {
        match self {
            Self::Real => z,
            Self::Positive => libm::exp(z),
            Self::Interval { low, high } => {
                let u = if z >= 0.0 {
                    1.0 / (1.0 + libm::exp(-z))
                } else {
                    let e = libm::exp(z);
                    e / (1.0 + e)
                };
                within(low + (high - low) * u, low, high)
            }
        }
    }

    /// `log |dz / dθ|` at `theta`: what a density over the unbounded space
    /// gains as one over the parameter (at the value the map clamps to).
    pub fn log_jacobian(self, theta: f64) -> f64 {
        match self {
            Self::Real => 0.0,
            Self::Positive => -libm::log(theta.max(Self::EDGE)),
            Self::Interval { low, high } => {
                let u = within((theta - low) / (high - low), Self::EDGE, 1.0 - Self::EDGE);
                -libm::log(u) - libm::log1p(-u) - libm::log(high - low)
            }
        }
    }
}

/// `x` kept within `[low, high]` as `f64::clamp` keeps it (a NaN stays
/// NaN), without its check that the bounds are ordered: that check's
/// panic message formats floats, and a microcontroller's firmware would
/// carry the float formatting for it (the callers' bounds are ordered;
/// docs/embedded.md has what it cost).
fn within(x: f64, low: f64, high: f64) -> f64 {
    let mut v = x;
    if v < low {
        v = low;
    }
    if v > high {
        v = high;
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 x 2 covariance's log density by its inverse and determinant
    /// written out, against the precision factor's.
    #[test]
    fn a_component_is_the_gaussian_of_its_covariance() {
        let shape = MixtureShape {
            components: 1,
            dim: 2,
        };
        // U = [[a, b], [0, c]]: Σ⁻¹ = U'U = [[a², ab], [ab, b² + c²]].
        let (a, b, c) = (1.7f64, -0.6f64, 0.8f64);
        let head = [0.3, 0.5, -1.0, a.ln(), c.ln(), b];
        let precision = [[a * a, a * b], [a * b, b * b + c * c]];
        let det_precision = precision[0][0] * precision[1][1] - precision[0][1].powi(2);
        let e = [0.9 - 0.5, -0.2 + 1.0];
        let quad = e[0] * e[0] * precision[0][0]
            + 2.0 * e[0] * e[1] * precision[0][1]
            + e[1] * e[1] * precision[1][1];
        let expected = 0.5 * det_precision.ln() - (2.0 * PI).ln() - 0.5 * quad;
        let got = shape.log_density(&head, &[0.9, -0.2]);
        assert!((got - expected).abs() < 1e-13, "{got} against {expected}");
    }

    /// Two components' density is their weighted sum, weights by softmax.
    #[test]
    fn the_mixture_weighs_its_components_by_softmax() {
        let shape = MixtureShape {
            components: 2,
            dim: 1,
        };
        let head = [0.2, -0.4, -1.0, 2.0, 0.1, -0.3];
        let normal = |z: f64, m: f64, s: f64| {
            (-(z - m).powi(2) / (2.0 * s * s)).exp() / (s * (2.0 * PI).sqrt())
        };
        let (w0, w1) = (0.2f64.exp(), (-0.4f64).exp());
        let z = 0.7;
        let expected =
            (w0 * normal(z, -1.0, (-0.1f64).exp()) + w1 * normal(z, 2.0, 0.3f64.exp())) / (w0 + w1);
        let got = shape.log_density(&head, &[z]).exp();
        assert!((got - expected).abs() < 1e-14 * expected.max(1.0));
    }

    /// A draw inverts the factor: `U (z − μ)` is the normals drawn with.
    #[test]
    fn a_draw_is_the_factor_solved_for_its_normals() {
        let shape = MixtureShape {
            components: 2,
            dim: 3,
        };
        let head: [f64; 2 * (1 + 6 + 3)] =
            core::array::from_fn(|i| ((i * 7 % 11) as f64 - 5.0) / 4.0);
        let normals = [0.4, -1.3, 2.1];
        let mut z = [0.0; 3];
        // A uniform of 0.999 takes the last component.
        shape.draw(&head, 0.999, &normals, &mut z);
        let c = 1;
        for i in 0..3 {
            let mean = head[shape.mean_at(c)..][..3].to_vec();
            let mut y = head[shape.log_diagonal_at(c) + i].exp() * (z[i] - mean[i]);
            for j in i + 1..3 {
                y += head[shape.upper_at(c) + shape.upper_index(i, j)] * (z[j] - mean[j]);
            }
            assert!((y - normals[i]).abs() < 1e-12, "{i}: {y}");
        }
    }

    #[test]
    fn the_upper_entries_are_numbered_row_by_row() {
        let shape = MixtureShape {
            components: 1,
            dim: 4,
        };
        let mut places = [(0, 0); 6];
        for i in 0..4 {
            for j in i + 1..4 {
                places[shape.upper_index(i, j)] = (i, j);
            }
        }
        assert_eq!(places, [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]);
        assert_eq!(shape.outputs(), 1 + 4 + 4 + 6);
    }

    /// The maps are each other's inverse, and the Jacobian is the
    /// derivative's logarithm by central differences.
    #[test]
    fn the_supports_map_back_and_forth_with_their_jacobian() {
        for (support, theta) in [
            (Support::Real, -3.2),
            (Support::Positive, 0.07),
            (
                Support::Interval {
                    low: 2.0,
                    high: 5.0,
                },
                4.1,
            ),
        ] {
            let z = support.to_unbounded(theta);
            assert!((support.from_unbounded(z) - theta).abs() < 1e-12);
            let h = 1e-6;
            let derivative =
                (support.to_unbounded(theta + h) - support.to_unbounded(theta - h)) / (2.0 * h);
            assert!(
                (support.log_jacobian(theta) - derivative.ln()).abs() < 1e-7,
                "{support:?}"
            );
        }
        // Extreme numbers stay within the interval.
        let box_ = Support::Interval {
            low: 2.0,
            high: 5.0,
        };
        for z in [-1e300, -800.0, 800.0, 1e300, f64::INFINITY] {
            let theta = box_.from_unbounded(z);
            assert!((2.0..=5.0).contains(&theta), "{z} -> {theta}");
        }
    }
}
