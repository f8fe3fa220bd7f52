//! Priors of the parameter vector (independent marginals inside a range
//! box) and the designs that sample them.

use crate::InvalidSetting;
use rand::{Rng, RngExt};

use crate::error::{Result, SimError};
use crate::marginal::Marginal;
use crate::rng::{ExperimentRng, StreamPurpose, stream_rng};
use crate::sobol::{self, Sobol};

/// How the `m` parameter vectors of a chart are placed in the prior box.
///
/// Stored in shard files by its serde index: new designs go at the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[non_exhaustive]
pub enum Sampling {
    /// Independent uniform draws (the paper's choice, Section 4.1).
    #[default]
    Uniform,
    /// Latin hypercube: each parameter's range is cut into `m` equal strata
    /// and each stratum holds exactly one experiment, jittered uniformly.
    LatinHypercube,
    /// Sobol low-discrepancy points (Joe-Kuo directions, at most
    /// [`Prior::MAX_SOBOL_DIMENSION`] parameters) with a random digital shift
    /// drawn from the seed, so that designs of different seeds differ.
    Sobol,
}

impl Sampling {
    /// The design's name as files and reports write it ("Uniform",
    /// "LatinHypercube", "Sobol"). Stable: a variant renamed in the code
    /// keeps its name here.
    pub fn name(self) -> &'static str {
        match self {
            Self::Uniform => "Uniform",
            Self::LatinHypercube => "LatinHypercube",
            Self::Sobol => "Sobol",
        }
    }
}

impl std::fmt::Display for Sampling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A prior of independent parameters, each with its [`Marginal`]
/// (uniform on the paper's box by default), and the [`Sampling`] used to
/// fill it. Every prior has a box, `[lower_j, upper_j]`: the support of a
/// bounded marginal, the central `1 - 2e-6` of an unbounded one
/// ([`Marginal::range`]). Charts are drawn inside it, estimates are clipped
/// to it, and certificates are stated on it.
///
/// ```
/// use twostage_models::{Prior, Sampling};
/// let prior = Prior::uniform_box(&[-0.9], &[0.9])?.with_sampling(Sampling::LatinHypercube);
/// let design = prior.design(1000, 7)?;
/// let mut theta = [0.0];
/// design.fill_theta(3, &mut theta)?;
/// assert!(prior.contains(&theta));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    marginals: Vec<Marginal>,
    lower: Vec<f64>,
    upper: Vec<f64>,
    sampling: Sampling,
}

impl Prior {
    /// The most parameters a [`Sampling::Sobol`] design supports.
    pub const MAX_SOBOL_DIMENSION: usize = sobol::MAX_DIMENSION;

    /// A uniform prior on the box with the given bounds, sampled i.i.d.
    ///
    /// # Errors
    /// [`SimError::InvalidPrior`] if the bound lists differ in length or are
    /// empty, a bound is not finite, or a lower bound is not below its upper bound.
    pub fn uniform_box(lower: &[f64], upper: &[f64]) -> Result<Self> {
        if lower.len() != upper.len() || lower.is_empty() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "prior box",
                value: format!("{} lower and {} upper bounds", lower.len(), upper.len()),
                reason: "give one lower and one upper bound per parameter, at least one parameter"
                    .into(),
            }));
        }
        for (index, (&lo, &hi)) in lower.iter().zip(upper).enumerate() {
            let reason = if !lo.is_finite() || !hi.is_finite() {
                Some("bounds must be finite numbers")
            } else if lo >= hi {
                Some("the lower bound must be below the upper bound")
            } else {
                None
            };
            if let Some(reason) = reason {
                return Err(SimError::InvalidPrior {
                    index,
                    lower: lo,
                    upper: hi,
                    reason,
                });
            }
        }
        Ok(Self {
            marginals: lower
                .iter()
                .zip(upper)
                .map(|(&low, &high)| Marginal::Uniform { low, high })
                .collect(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            sampling: Sampling::Uniform,
        })
    }

    /// A prior of independent parameters with the given marginals, sampled
    /// i.i.d.
    ///
    /// ```
    /// use twostage_models::{Marginal, Prior, Sampling};
    /// let prior = Prior::new(vec![
    ///     Marginal::LogNormal { mu: -0.916, sigma: 0.5 },
    ///     Marginal::Uniform { low: 0.05, high: 0.3 },
    /// ])?
    /// .with_sampling(Sampling::Sobol);
    /// let design = prior.design(256, 1)?;
    /// let mut theta = [0.0; 2];
    /// design.fill_theta(0, &mut theta)?;
    /// assert!(theta[0] > 0.0 && prior.contains(&theta));
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    ///
    /// # Errors
    /// [`SimError::InvalidMarginal`] for a malformed marginal, naming its
    /// index; [`SimError::InvalidSetting`] for no parameter at all.
    pub fn new(marginals: Vec<Marginal>) -> Result<Self> {
        if marginals.is_empty() {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "prior",
                value: "no parameter".into(),
                reason: "give at least one parameter".into(),
            }));
        }
        for (index, m) in marginals.iter().enumerate() {
            m.check(index)?;
        }
        let (lower, upper) = marginals.iter().map(Marginal::range).unzip();
        Ok(Self {
            marginals,
            lower,
            upper,
            sampling: Sampling::Uniform,
        })
    }

    /// Each parameter's marginal distribution.
    pub fn marginals(&self) -> &[Marginal] {
        &self.marginals
    }

    /// Whether every marginal is uniform: the paper's prior box.
    pub fn is_uniform_box(&self) -> bool {
        self.marginals
            .iter()
            .all(|m| matches!(m, Marginal::Uniform { .. }))
    }

    /// The same box, sampled by another design.
    pub fn with_sampling(mut self, sampling: Sampling) -> Self {
        self.sampling = sampling;
        self
    }

    /// Number of parameters q.
    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// Lower bounds of the box (see the type's documentation).
    pub fn lower(&self) -> &[f64] {
        &self.lower
    }

    /// Upper bounds of the box.
    pub fn upper(&self) -> &[f64] {
        &self.upper
    }

    /// The sampling design.
    pub fn sampling(&self) -> Sampling {
        self.sampling
    }

    /// Whether `theta` lies in the (closed) box.
    pub fn contains(&self, theta: &[f64]) -> bool {
        theta.len() == self.dim()
            && theta
                .iter()
                .zip(self.lower.iter().zip(&self.upper))
                .all(|(t, (lo, hi))| *lo <= *t && *t <= *hi)
    }

    /// Clip `theta` to the box, component by component; a NaN becomes the
    /// centre of its interval (`twostage_kernels::vector::clip_to_box`).
    pub fn clip(&self, theta: &mut [f64]) {
        twostage_kernels::vector::clip_to_box(theta, &self.lower[..], &self.upper[..]);
    }

    /// Check a user-given parameter vector: its length, finiteness and,
    /// unless `allow_outside` is set, that it lies in the box.
    ///
    /// # Errors
    /// [`SimError::WrongParameterCount`], [`SimError::NonFiniteParameter`]
    /// or [`SimError::OutsidePrior`], naming the parameter.
    pub fn check(&self, theta: &[f64], names: &[String], allow_outside: bool) -> Result<()> {
        if theta.len() != self.dim() {
            return Err(SimError::WrongParameterCount {
                expected: self.dim(),
                got: theta.len(),
                names: names.join(","),
            });
        }
        let name = |j: usize| names.get(j).cloned().unwrap_or_else(|| format!("#{j}"));
        for (j, &value) in theta.iter().enumerate() {
            if !value.is_finite() {
                return Err(SimError::NonFiniteParameter {
                    name: name(j),
                    value,
                });
            }
            let (lower, upper) = (self.lower[j], self.upper[j]);
            if !allow_outside && !(lower..=upper).contains(&value) {
                return Err(SimError::OutsidePrior {
                    name: name(j),
                    value,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }

    /// The design of a chart of `m` experiments with seed `seed`.
    ///
    /// Parameter vector `i` depends only on `(seed, i, m)`: never on the
    /// thread count or on the order in which experiments are run.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] if `m` is zero, or too large for the
    /// design (Sobol: `m <= 2^32`), or the prior has more parameters than
    /// [`Prior::MAX_SOBOL_DIMENSION`] for a Sobol design.
    pub fn design(&self, m: usize, seed: u64) -> Result<Design> {
        if m == 0 {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "m",
                value: "0".into(),
                reason: "a design needs at least one experiment".into(),
            }));
        }
        let mut design_rng = stream_rng(seed, 0, StreamPurpose::Design);
        let kind = match self.sampling {
            Sampling::Uniform => DesignKind::Uniform,
            Sampling::LatinHypercube => {
                let strata = (0..self.dim())
                    .map(|_| random_permutation(m, &mut design_rng))
                    .collect();
                DesignKind::LatinHypercube { strata }
            }
            Sampling::Sobol => {
                if self.dim() > Self::MAX_SOBOL_DIMENSION {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "sampling",
                        value: format!("Sobol with {} parameters", self.dim()),
                        reason: format!(
                            "Sobol designs support at most {} parameters: use the \
                             Latin hypercube or uniform design",
                            Self::MAX_SOBOL_DIMENSION
                        ),
                    }));
                }
                if u32::try_from(m).is_err() {
                    return Err(SimError::InvalidSetting(InvalidSetting {
                        name: "m",
                        value: m.to_string(),
                        reason: "Sobol designs hold at most 2^32 - 1 points".into(),
                    }));
                }
                let shifts = (0..self.dim()).map(|_| design_rng.next_u32()).collect();
                DesignKind::Sobol {
                    sobol: Sobol::new(self.dim()),
                    shifts,
                }
            }
        };
        Ok(Design {
            prior: self.clone(),
            m,
            seed,
            kind,
        })
    }
}

#[derive(Debug, Clone)]
enum DesignKind {
    Uniform,
    LatinHypercube { strata: Vec<Vec<u32>> },
    Sobol { sobol: Sobol, shifts: Vec<u32> },
}

/// The parameter vectors of one chart: `m` points in the prior box, each
/// computed on demand from its index.
#[derive(Debug, Clone)]
pub struct Design {
    prior: Prior,
    m: usize,
    seed: u64,
    kind: DesignKind,
}

impl Design {
    /// Number of experiments m.
    pub fn len(&self) -> usize {
        self.m
    }

    /// Whether the design is empty (never: `Prior::design` rejects m = 0).
    pub fn is_empty(&self) -> bool {
        self.m == 0
    }

    /// The seed of the chart.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The prior this design samples.
    pub fn prior(&self) -> &Prior {
        &self.prior
    }

    /// Write parameter vector `index` into `theta`.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] if `index >= m` or `theta` does not have
    /// one slot per parameter.
    pub fn fill_theta(&self, index: usize, theta: &mut [f64]) -> Result<()> {
        if index >= self.m {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "experiment index",
                value: index.to_string(),
                reason: format!("the design holds experiments 0..{}", self.m),
            }));
        }
        if theta.len() != self.prior.dim() {
            return Err(SimError::WrongParameterCount {
                expected: self.prior.dim(),
                got: theta.len(),
                names: String::new(),
            });
        }
        let mut rng: ExperimentRng = stream_rng(self.seed, index as u64, StreamPurpose::Parameter);
        for (j, t) in theta.iter_mut().enumerate() {
            let unit = match &self.kind {
                DesignKind::Uniform => rng.random::<f64>(),
                DesignKind::LatinHypercube { strata } => {
                    (f64::from(strata[j][index]) + rng.random::<f64>()) / self.m as f64
                }
                DesignKind::Sobol { sobol, shifts } => {
                    // `design` checked that m, and so index, fits in u32.
                    let bits = sobol.coordinate_bits(index as u32, j) ^ shifts[j];
                    // Centre of the 2^-32 cell, so no point sits on the boundary.
                    (f64::from(bits) + 0.5) * sobol::UNIT
                }
            };
            *t = self.prior.marginals[j].from_unit(unit);
        }
        Ok(())
    }
}

/// A uniformly random permutation of 0..m (Fisher-Yates), drawn from `rng`:
/// the Latin hypercube's strata, and the held-out split of a chart.
///
/// ```
/// use twostage_models::{random_permutation, experiment_rng};
/// let p = random_permutation(5, &mut experiment_rng(1, 0));
/// let mut sorted = p.clone();
/// sorted.sort_unstable();
/// assert_eq!(sorted, [0, 1, 2, 3, 4]);
/// ```
pub fn random_permutation(m: usize, rng: &mut ExperimentRng) -> Vec<u32> {
    // Strata are stored as u32 to halve the memory of large designs; a design
    // of more than 2^32 experiments would not fit in memory anyway.
    let mut p: Vec<u32> = (0..m).map(|i| i as u32).collect();
    for i in (1..m).rev() {
        let j = rng.random_range(0..=i);
        p.swap(i, j);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Estimator files hold these names (written before they existed as
    /// the designs' debug text): they never change.
    #[test]
    fn designs_keep_the_names_files_hold() {
        let names: Vec<&str> = [Sampling::Uniform, Sampling::LatinHypercube, Sampling::Sobol]
            .iter()
            .map(|s| s.name())
            .collect();
        assert_eq!(names, ["Uniform", "LatinHypercube", "Sobol"]);
        assert_eq!(Sampling::Sobol.to_string(), "Sobol");
    }

    fn draws(prior: &Prior, m: usize, seed: u64) -> Vec<Vec<f64>> {
        let design = prior.design(m, seed).unwrap();
        (0..m)
            .map(|i| {
                let mut t = vec![0.0; prior.dim()];
                design.fill_theta(i, &mut t).unwrap();
                t
            })
            .collect()
    }

    #[test]
    fn every_design_stays_in_the_box_and_is_reproducible() {
        for sampling in [Sampling::Uniform, Sampling::LatinHypercube, Sampling::Sobol] {
            let prior = Prior::uniform_box(&[-42.83, -1.22], &[-27.32, -0.98])
                .unwrap()
                .with_sampling(sampling);
            let a = draws(&prior, 500, 11);
            assert!(a.iter().all(|t| prior.contains(t)), "{sampling:?}");
            assert_eq!(a, draws(&prior, 500, 11), "{sampling:?}");
            assert_ne!(a, draws(&prior, 500, 12), "{sampling:?}");
        }
    }

    #[test]
    fn latin_hypercube_puts_one_point_per_stratum() {
        let prior = Prior::uniform_box(&[0.0, 10.0], &[1.0, 30.0])
            .unwrap()
            .with_sampling(Sampling::LatinHypercube);
        let m = 97;
        let points = draws(&prior, m, 3);
        for j in 0..2 {
            let (lo, hi) = (prior.lower()[j], prior.upper()[j]);
            let mut counts = vec![0; m];
            for t in &points {
                let cell = (((t[j] - lo) / (hi - lo)) * m as f64).floor() as usize;
                counts[cell.min(m - 1)] += 1;
            }
            assert!(counts.iter().all(|&c| c == 1), "parameter {j}: {counts:?}");
        }
    }

    #[test]
    fn uniform_draws_have_the_uniform_mean_and_variance() {
        let prior = Prior::uniform_box(&[-0.9], &[0.9]).unwrap();
        let m = 40_000;
        let x: Vec<f64> = draws(&prior, m, 5).into_iter().map(|t| t[0]).collect();
        let mean = x.iter().sum::<f64>() / m as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (m - 1) as f64;
        // Uniform on [-0.9, 0.9]: mean 0, variance 1.8^2 / 12 = 0.27.
        // Standard errors: 0.0026 for the mean, about 0.0012 for the variance.
        assert!(mean.abs() < 0.013, "mean {mean}");
        assert!((var - 0.27).abs() < 0.006, "variance {var}");
    }

    #[test]
    fn sobol_design_covers_the_box_evenly() {
        let prior = Prior::uniform_box(&[0.0, 0.0], &[1.0, 1.0])
            .unwrap()
            .with_sampling(Sampling::Sobol);
        let points = draws(&prior, 256, 9);
        // A digitally shifted (0, 8, 2)-net: one point in every 16 x 16 cell.
        let mut seen = [[false; 16]; 16];
        for t in &points {
            let (a, b) = ((t[0] * 16.0) as usize, (t[1] * 16.0) as usize);
            assert!(!seen[a][b], "two points in cell ({a}, {b})");
            seen[a][b] = true;
        }
    }

    #[test]
    fn malformed_boxes_and_values_are_rejected_with_their_names() {
        assert!(Prior::uniform_box(&[1.0], &[0.0]).is_err());
        assert!(Prior::uniform_box(&[f64::NAN], &[0.0]).is_err());
        assert!(Prior::uniform_box(&[0.0, 1.0], &[1.0]).is_err());
        let prior = Prior::uniform_box(&[-0.9], &[0.9]).unwrap();
        let names = vec!["theta".to_string()];
        let err = prior.check(&[1.5], &names, false).unwrap_err();
        assert!(err.to_string().contains("theta = 1.5"), "{err}");
        assert!(prior.check(&[1.5], &names, true).is_ok());
        assert!(prior.check(&[0.1, 0.2], &names, false).is_err());
        assert!(prior.check(&[f64::INFINITY], &names, true).is_err());
        assert!(prior.design(0, 1).is_err());
    }

    #[test]
    fn designs_of_general_priors_have_their_moments_and_strata_by_probability() {
        let (mu, sigma) = (2.0, 0.5);
        let prior = Prior::new(vec![
            Marginal::Normal { mu, sigma },
            Marginal::LogNormal {
                mu: -1.0,
                sigma: 0.3,
            },
            Marginal::TruncatedNormal {
                mu: 0.0,
                sigma: 1.0,
                low: 0.0,
                high: 10.0,
            },
        ])
        .unwrap();
        assert!(!prior.is_uniform_box());
        let m = 40_000;
        for sampling in [Sampling::Uniform, Sampling::LatinHypercube, Sampling::Sobol] {
            let points = draws(&prior.clone().with_sampling(sampling), m, 8);
            assert!(points.iter().all(|t| prior.contains(t)), "{sampling:?}");
            let mean = |j: usize| points.iter().map(|t| t[j]).sum::<f64>() / m as f64;
            let var = |j: usize, c: f64| {
                points.iter().map(|t| (t[j] - c).powi(2)).sum::<f64>() / (m - 1) as f64
            };
            // Normal: standard errors 0.0025 (mean) and 0.0018 (variance).
            assert!((mean(0) - mu).abs() < 0.0125, "{sampling:?} {}", mean(0));
            assert!(
                (var(0, mean(0)) - sigma * sigma).abs() < 0.009,
                "{sampling:?}"
            );
            // Log-normal: mean exp(mu + s^2 / 2).
            let expected = (-1.0f64 + 0.045).exp();
            assert!(
                (mean(1) / expected - 1.0).abs() < 0.005,
                "{sampling:?} {}",
                mean(1)
            );
            // Half-normal: mean sqrt(2 / pi), variance 1 - 2 / pi.
            let half = (2.0 / std::f64::consts::PI).sqrt();
            assert!((mean(2) - half).abs() < 0.01, "{sampling:?} {}", mean(2));
            assert!(
                (var(2, half) - (1.0 - half * half)).abs() < 0.01,
                "{sampling:?}"
            );
        }
        // A Latin hypercube places one point per stratum of probability.
        let lhs = prior.with_sampling(Sampling::LatinHypercube);
        let m = 101;
        let points = draws(&lhs, m, 2);
        for j in 0..3 {
            let marginal = lhs.marginals()[j];
            let tail = if marginal.is_bounded() {
                0.0
            } else {
                crate::UNBOUNDED_TAIL
            };
            let mut counts = vec![0; m];
            for t in &points {
                let u = (marginal.cdf(t[j]) - tail) / (1.0 - 2.0 * tail);
                counts[((u * m as f64).floor() as usize).min(m - 1)] += 1;
            }
            assert!(counts.iter().all(|&c| c == 1), "parameter {j}: {counts:?}");
        }
    }

    #[test]
    fn a_uniform_box_is_the_prior_of_uniform_marginals() {
        let by_box = Prior::uniform_box(&[-1.0, 2.0], &[1.0, 5.0]).unwrap();
        let by_marginals = Prior::new(vec![
            Marginal::Uniform {
                low: -1.0,
                high: 1.0,
            },
            Marginal::Uniform {
                low: 2.0,
                high: 5.0,
            },
        ])
        .unwrap();
        assert_eq!(by_box, by_marginals);
        assert!(by_box.is_uniform_box());
        assert!(Prior::new(vec![]).is_err());
        let e = Prior::new(vec![
            Marginal::Uniform {
                low: 0.0,
                high: 1.0,
            },
            Marginal::Normal {
                mu: 0.0,
                sigma: -1.0,
            },
        ])
        .unwrap_err();
        assert!(e.to_string().contains("parameter 1"), "{e}");
    }
}
