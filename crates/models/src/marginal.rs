//! One parameter's prior: uniform, normal, log-normal or truncated normal,
//! sampled through its inverse CDF so that every design (uniform draws,
//! Latin hypercube, Sobol) places points by probability, not by value.

use crate::error::{Result, SimError};
use twostage_kernels::mixture::Support;

/// The probability left out in each tail of an unbounded prior: charts are
/// drawn from the prior truncated to its central `1 - 2e-6` range, and that
/// range is the box estimates are clipped to and certificates are stated
/// on (docs/decisions/018-general-priors.md).
pub const UNBOUNDED_TAIL: f64 = 1e-6;

/// The prior of one parameter.
///
/// ```
/// use twostage_models::Marginal;
/// let beta = Marginal::LogNormal { mu: -0.916, sigma: 0.5 };
/// beta.check(0)?;
/// // The median of a log-normal is exp(mu).
/// assert!((beta.quantile(0.5) - (-0.916f64).exp()).abs() < 1e-12);
/// // Its range: the central 1 - 2e-6, positive as the parameter is.
/// let (low, high) = beta.range();
/// assert!(0.0 < low && low < 0.04 && high > 4.0);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Marginal {
    /// Uniform on `[low, high]` (the paper's choice).
    Uniform {
        /// Lower bound.
        low: f64,
        /// Upper bound.
        high: f64,
    },
    /// Normal with mean `mu` and standard deviation `sigma`.
    Normal {
        /// Mean.
        mu: f64,
        /// Standard deviation, > 0.
        sigma: f64,
    },
    /// `exp(X)` with `X` normal(`mu`, `sigma`): a positive parameter whose
    /// order of magnitude is uncertain.
    LogNormal {
        /// Mean of the logarithm.
        mu: f64,
        /// Standard deviation of the logarithm, > 0.
        sigma: f64,
    },
    /// Normal(`mu`, `sigma`) conditioned on `[low, high]`.
    TruncatedNormal {
        /// Mean before truncation.
        mu: f64,
        /// Standard deviation before truncation, > 0.
        sigma: f64,
        /// Lower bound.
        low: f64,
        /// Upper bound.
        high: f64,
    },
}

/// The space the stage-2 map learns a parameter in: one where every value
/// maps back into the prior's support.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transform {
    /// The parameter itself.
    Identity,
    /// Its logarithm (a positive parameter).
    Log,
}

impl Transform {
    /// From the parameter to the learning space.
    #[inline]
    pub fn forward(self, theta: f64) -> f64 {
        match self {
            Transform::Identity => theta,
            Transform::Log => theta.ln(),
        }
    }

    /// From the learning space back to the parameter.
    #[inline]
    pub fn inverse(self, z: f64) -> f64 {
        match self {
            Transform::Identity => z,
            Transform::Log => z.exp(),
        }
    }
}

impl Marginal {
    /// The distribution's name as a model file writes it.
    pub fn name(&self) -> &'static str {
        match self {
            Marginal::Uniform { .. } => "uniform",
            Marginal::Normal { .. } => "normal",
            Marginal::LogNormal { .. } => "lognormal",
            Marginal::TruncatedNormal { .. } => "truncnormal",
        }
    }

    /// Check the parameters of parameter `index`'s prior.
    ///
    /// # Errors
    /// [`SimError::InvalidMarginal`] naming the parameter index, the
    /// distribution and what is accepted.
    pub fn check(&self, index: usize) -> Result<()> {
        let fail = |reason: &'static str| {
            Err(SimError::InvalidMarginal {
                index,
                marginal: self.to_string(),
                reason,
            })
        };
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match *self {
            Marginal::Uniform { low, high } => {
                if !finite(&[low, high]) {
                    return fail("bounds must be finite numbers");
                }
                if low >= high {
                    return fail("the lower bound must be below the upper bound");
                }
            }
            Marginal::Normal { mu, sigma } | Marginal::LogNormal { mu, sigma } => {
                if !finite(&[mu, sigma]) || sigma <= 0.0 {
                    return fail("mu must be finite and sigma finite and > 0");
                }
            }
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => {
                if !finite(&[mu, sigma, low, high]) || sigma <= 0.0 {
                    return fail("mu, low and high must be finite and sigma finite and > 0");
                }
                if low >= high {
                    return fail("the lower bound must be below the upper bound");
                }
                let (a, b) = ((low - mu) / sigma, (high - mu) / sigma);
                // Beyond 37 sd the normal's mass underflows to zero.
                if a > 37.0 || b < -37.0 {
                    return fail("[low, high] lies more than 37 sd from mu: no mass to sample");
                }
            }
        }
        Ok(())
    }

    /// The value below which the prior puts probability `p` (0 < p < 1),
    /// of the distribution itself (not truncated to [`Marginal::range`]).
    pub fn quantile(&self, p: f64) -> f64 {
        match *self {
            Marginal::Uniform { low, high } => low + p * (high - low),
            Marginal::Normal { mu, sigma } => mu + sigma * standard_normal_quantile(p),
            Marginal::LogNormal { mu, sigma } => (mu + sigma * standard_normal_quantile(p)).exp(),
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => {
                let z = truncated_standard_quantile((low - mu) / sigma, (high - mu) / sigma, p);
                (mu + sigma * z).clamp(low, high)
            }
        }
    }

    /// The log density of the prior at `z` of the unbounded space its
    /// [`Marginal::support`] maps it to (a log-normal parameter's
    /// logarithm, the logit of the place in a bounded one's interval): what
    /// a likelihood over that space is multiplied by.
    ///
    /// ```
    /// use twostage_models::Marginal;
    /// // Uniform on [2, 4]: the logit of the place is logistic, 1/4 at 0.
    /// let uniform = Marginal::Uniform { low: 2.0, high: 4.0 };
    /// assert!((uniform.unbounded_log_density(0.0) - 0.25f64.ln()).abs() < 1e-15);
    /// // Log-normal: its logarithm is normal.
    /// let lognormal = Marginal::LogNormal { mu: 1.0, sigma: 2.0 };
    /// let normal = Marginal::Normal { mu: 1.0, sigma: 2.0 };
    /// assert_eq!(lognormal.unbounded_log_density(0.3), normal.unbounded_log_density(0.3));
    /// ```
    pub fn unbounded_log_density(&self, z: f64) -> f64 {
        let normal = |x: f64, mu: f64, sigma: f64| {
            let r = (x - mu) / sigma;
            -0.5 * r * r - sigma.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
        };
        // ln u + ln(1 - u) for u the logistic of z, without overflow.
        let log_logistic_density = -z.abs() - 2.0 * (-z.abs()).exp().ln_1p();
        match *self {
            Marginal::Normal { mu, sigma } | Marginal::LogNormal { mu, sigma } => {
                normal(z, mu, sigma)
            }
            Marginal::Uniform { .. } => log_logistic_density,
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => {
                let theta = self.support().from_unbounded(z);
                normal(theta, mu, sigma) - truncated_mass(mu, sigma, low, high).ln()
                    + (high - low).ln()
                    + log_logistic_density
            }
        }
    }

    /// The largest value [`Marginal::unbounded_log_density`] takes (for
    /// a truncated normal, a bound: the product of its factors' largest).
    pub fn unbounded_log_density_peak(&self) -> f64 {
        let quarter = 0.25f64.ln();
        let normal_peak = |sigma: f64| -sigma.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
        match *self {
            Marginal::Normal { sigma, .. } | Marginal::LogNormal { sigma, .. } => {
                normal_peak(sigma)
            }
            Marginal::Uniform { .. } => quarter,
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => {
                normal_peak(sigma) - truncated_mass(mu, sigma, low, high).ln()
                    + (high - low).ln()
                    + quarter
            }
        }
    }

    /// The probability the prior puts below `x`.
    pub fn cdf(&self, x: f64) -> f64 {
        match *self {
            Marginal::Uniform { low, high } => ((x - low) / (high - low)).clamp(0.0, 1.0),
            Marginal::Normal { mu, sigma } => standard_normal_cdf((x - mu) / sigma),
            Marginal::LogNormal { mu, sigma } => {
                if x <= 0.0 {
                    0.0
                } else {
                    standard_normal_cdf((x.ln() - mu) / sigma)
                }
            }
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => {
                if x <= low {
                    return 0.0;
                }
                if x >= high {
                    return 1.0;
                }
                let (z, a, b) = ((x - mu) / sigma, (low - mu) / sigma, (high - mu) / sigma);
                let share = if a > 0.0 {
                    // In the upper tail, by the survival function (see
                    // truncated_standard_quantile).
                    let q = |v: f64| standard_normal_cdf(-v);
                    (q(a) - q(z)) / (q(a) - q(b))
                } else {
                    let p = standard_normal_cdf;
                    (p(z) - p(a)) / (p(b) - p(a))
                };
                share.clamp(0.0, 1.0)
            }
        }
    }

    /// Whether the support is a bounded interval.
    pub fn is_bounded(&self) -> bool {
        matches!(
            self,
            Marginal::Uniform { .. } | Marginal::TruncatedNormal { .. }
        )
    }

    /// The range charts are drawn from: the support when it is bounded,
    /// otherwise the central `1 - 2 UNBOUNDED_TAIL` of the distribution.
    pub fn range(&self) -> (f64, f64) {
        match *self {
            Marginal::Uniform { low, high } | Marginal::TruncatedNormal { low, high, .. } => {
                (low, high)
            }
            Marginal::Normal { .. } | Marginal::LogNormal { .. } => (
                self.quantile(UNBOUNDED_TAIL),
                self.quantile(1.0 - UNBOUNDED_TAIL),
            ),
        }
    }

    /// The point of [`Marginal::range`] at probability `unit` in [0, 1) of
    /// the prior restricted to it: how a design's unit coordinate becomes a
    /// parameter value.
    #[inline]
    pub fn from_unit(&self, unit: f64) -> f64 {
        match *self {
            // The paper's uniform box, kept as the linear map it always was.
            Marginal::Uniform { low, high } => low + unit * (high - low),
            Marginal::TruncatedNormal { .. } => self.quantile(unit),
            Marginal::Normal { .. } | Marginal::LogNormal { .. } => {
                let (low, high) = self.range();
                self.quantile(UNBOUNDED_TAIL + unit * (1.0 - 2.0 * UNBOUNDED_TAIL))
                    .clamp(low, high)
            }
        }
    }

    /// The space the stage-2 map learns this parameter in.
    pub fn transform(&self) -> Transform {
        match self {
            Marginal::LogNormal { .. } => Transform::Log,
            _ => Transform::Identity,
        }
    }
}

impl Marginal {
    /// Where the parameter's values lie: the whole line (normal), the
    /// positive numbers (log-normal) or an interval (uniform, truncated
    /// normal). A density over the parameter lives on the real line this
    /// maps to ([`Support::to_unbounded`]), so its draws never leave it.
    ///
    /// ```
    /// use twostage_models::Marginal;
    /// use twostage_kernels::mixture::Support;
    /// let rate = Marginal::LogNormal { mu: 0.0, sigma: 1.0 };
    /// assert_eq!(rate.support(), Support::Positive);
    /// assert_eq!(
    ///     Marginal::Uniform { low: 1.0, high: 2.0 }.support(),
    ///     Support::Interval { low: 1.0, high: 2.0 }
    /// );
    /// ```
    pub fn support(&self) -> Support {
        match *self {
            Marginal::Uniform { low, high } | Marginal::TruncatedNormal { low, high, .. } => {
                Support::Interval { low, high }
            }
            Marginal::Normal { .. } => Support::Real,
            Marginal::LogNormal { .. } => Support::Positive,
        }
    }
}

impl std::fmt::Display for Marginal {
    /// As a model file would write it, e.g. `lognormal(mu = -0.916, sigma = 0.5)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Marginal::Uniform { low, high } => write!(f, "uniform on [{low}, {high}]"),
            Marginal::Normal { mu, sigma } => write!(f, "normal(mu = {mu}, sigma = {sigma})"),
            Marginal::LogNormal { mu, sigma } => {
                write!(f, "lognormal(mu = {mu}, sigma = {sigma})")
            }
            Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            } => write!(
                f,
                "truncnormal(mu = {mu}, sigma = {sigma}) on [{low}, {high}]"
            ),
        }
    }
}

/// The probability a normal(mu, sigma) puts in [low, high].
fn truncated_mass(mu: f64, sigma: f64, low: f64, high: f64) -> f64 {
    standard_normal_cdf((high - mu) / sigma) - standard_normal_cdf((low - mu) / sigma)
}

/// The standard normal CDF, `erfc(-x / sqrt 2) / 2`: accurate in both tails
/// to the relative precision of libm's `erfc`.
pub fn standard_normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// The standard normal quantile, the inverse of [`standard_normal_cdf`]:
/// Acklam's rational approximation (relative error below 1.2e-9) refined
/// by one Halley step on the exact CDF, which leaves a few ulps. 0 and 1
/// give the infinities, values outside [0, 1] NaN.
///
/// ```
/// use twostage_models::{standard_normal_cdf, standard_normal_quantile};
/// assert!((standard_normal_quantile(0.975) - 1.959963984540054).abs() < 1e-14);
/// let x = standard_normal_quantile(1e-10);
/// assert!((standard_normal_cdf(x) / 1e-10 - 1.0).abs() < 1e-13);
/// ```
pub fn standard_normal_quantile(p: f64) -> f64 {
    if p.is_nan() || !(0.0..=1.0).contains(&p) {
        return f64::NAN;
    }
    if p == 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    // The upper half by symmetry, so that the tail is always the lower one,
    // where p carries its full relative precision.
    if p > 0.5 {
        return -standard_normal_quantile(1.0 - p);
    }
    // P. J. Acklam, "An algorithm for computing the inverse normal
    // cumulative distribution function" (2003): coefficients of the central
    // and tail rational approximations.
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const P_LOW: f64 = 0.02425;
    let x = if p < P_LOW {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    // One Halley step on F(x) - p, with F' = phi and F'' = -x phi.
    let e = standard_normal_cdf(x) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (0.5 * x * x).exp();
    x - u / (1.0 + 0.5 * x * u)
}

/// The quantile `p` of the chi-square distribution of `dof` degrees of
/// freedom, by Wilson and Hilferty's cube-root normal approximation ("The
/// distribution of chi-square", PNAS 17, 1931): `dof (1 - 2/(9 dof) + z
/// sqrt(2/(9 dof)))^3`, `z` the standard normal quantile: for p from 0.9
/// to 0.999 its tail probability within 20% of `1 - p` (the worst at one
/// degree of freedom, where the quantile is 3% high at 0.999), within 10%
/// from nine degrees of freedom on. NaN for a `dof` of 0.
///
/// ```
/// use twostage_models::chi_square_quantile;
/// // The tables' 21.666 (9 degrees of freedom, 99%) and 6.635 (1, 99%).
/// assert!((chi_square_quantile(0.99, 9) / 21.666 - 1.0).abs() < 0.003);
/// assert!((chi_square_quantile(0.99, 1) / 6.635 - 1.0).abs() < 0.01);
/// ```
pub fn chi_square_quantile(p: f64, dof: usize) -> f64 {
    if dof == 0 {
        return f64::NAN;
    }
    let k = dof as f64;
    let spread = (2.0 / (9.0 * k)).sqrt();
    let root = 1.0 - 2.0 / (9.0 * k) + standard_normal_quantile(p) * spread;
    k * root.max(0.0).powi(3)
}

/// The mean of the standard normal conditioned on `[a, b]`, `(phi(a) -
/// phi(b)) / (Phi(b) - Phi(a))` (Johnson, Kotz and Balakrishnan,
/// Continuous Univariate Distributions 1, 2nd ed., 1994, sec. 13.10);
/// `None` where the interval holds no mass the doubles can tell.
///
/// ```
/// use twostage_models::truncated_standard_mean;
/// // Above 0: the half-normal's mean, sqrt(2 / pi).
/// let half = truncated_standard_mean(0.0, f64::INFINITY).unwrap();
/// assert!((half - (2.0 / std::f64::consts::PI).sqrt()).abs() < 1e-15);
/// // Symmetric bounds: 0.
/// assert_eq!(truncated_standard_mean(-1.5, 1.5), Some(0.0));
/// ```
pub fn truncated_standard_mean(a: f64, b: f64) -> Option<f64> {
    // With the interval in the upper tail, mirror it, as the quantile does.
    if a > 0.0 {
        return truncated_standard_mean(-b, -a).map(|m| -m);
    }
    let density = |z: f64| (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let mass = standard_normal_cdf(b) - standard_normal_cdf(a);
    let mean = (density(a) - density(b)) / mass;
    (mass > 0.0 && mean.is_finite()).then_some(mean.clamp(a, b))
}

/// The quantile at `p` of the standard normal conditioned on `[a, b]`.
fn truncated_standard_quantile(a: f64, b: f64, p: f64) -> f64 {
    // With the interval in the upper tail, mirror it: the lower tail's CDF
    // values keep their relative precision where 1 - CDF would round to 0.
    if a > 0.0 {
        return -truncated_standard_quantile(-b, -a, 1.0 - p);
    }
    let (fa, fb) = (standard_normal_cdf(a), standard_normal_cdf(b));
    standard_normal_quantile(fa + p * (fb - fa)).clamp(a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each prior's density over its unbounded space integrates to 1, and
    /// the parameter's mean under it is the distribution's own: the
    /// midpoint of a uniform, the closed-form mean of a truncated normal,
    /// exp(mu + sigma^2 / 2) of a log-normal.
    #[test]
    fn the_unbounded_density_is_the_prior_carried_over() {
        let truncated = Marginal::TruncatedNormal {
            mu: 1.0,
            sigma: 2.0,
            low: 0.5,
            high: 6.0,
        };
        let truncated_mean =
            1.0 + 2.0 * truncated_standard_mean(-0.25, 2.5).expect("a finite interval");
        let cases = [
            (
                Marginal::Uniform {
                    low: -3.0,
                    high: 5.0,
                },
                1.0,
            ),
            (truncated, truncated_mean),
            (
                Marginal::LogNormal {
                    mu: 0.3,
                    sigma: 0.4,
                },
                (0.3f64 + 0.08).exp(),
            ),
            (
                Marginal::Normal {
                    mu: -2.0,
                    sigma: 0.5,
                },
                -2.0,
            ),
        ];
        for (marginal, mean) in cases {
            let (h, cells) = (1e-3, 80_000);
            let (mut mass, mut first) = (0.0, 0.0);
            let peak = marginal.unbounded_log_density_peak();
            for k in 0..=cells {
                let z = -40.0 + k as f64 * h;
                assert!(
                    marginal.unbounded_log_density(z) <= peak + 1e-12,
                    "{marginal} at {z}"
                );
                let weight = if k == 0 || k == cells { 0.5 } else { 1.0 };
                let p = weight * h * marginal.unbounded_log_density(z).exp();
                mass += p;
                first += p * marginal.support().from_unbounded(z);
            }
            assert!((mass - 1.0).abs() < 1e-9, "{marginal}: mass {mass}");
            assert!(
                (first - mean).abs() < 1e-8,
                "{marginal}: mean {first} against {mean}"
            );
        }
    }

    /// The chi-square CDF at the approximate quantile, by Simpson's rule
    /// on the density (the substitution `x = t^2` takes away the
    /// singularity of one degree of freedom at 0), lands within a few
    /// thousandths of the probability asked.
    #[test]
    fn the_chi_square_quantile_holds_its_probability() {
        for dof in [1usize, 2, 3, 5, 9, 30] {
            for p in [0.9, 0.99, 0.999] {
                let x = chi_square_quantile(p, dof);
                let k = dof as f64;
                let log_norm = (k / 2.0) * std::f64::consts::LN_2 + libm::lgamma(k / 2.0);
                // Density of t = sqrt(x): 2 t f(t^2).
                let density = |t: f64| {
                    if t == 0.0 {
                        return if dof == 1 {
                            2.0 * (-log_norm).exp()
                        } else {
                            0.0
                        };
                    }
                    let x = t * t;
                    2.0 * t * ((k / 2.0 - 1.0) * x.ln() - x / 2.0 - log_norm).exp()
                };
                let (end, cells) = (x.sqrt(), 20_000);
                let h = end / cells as f64;
                let inner: f64 = (1..cells)
                    .map(|i| density(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 })
                    .sum();
                let cdf = h / 3.0 * (density(0.0) + inner + density(end));
                let tail = 1.0 - p;
                // The cube root is a rough fit of one degree of freedom's
                // far tail, and a close one from nine on.
                let allowed = if dof >= 9 { 0.1 } else { 0.2 };
                assert!(
                    ((1.0 - cdf) / tail - 1.0).abs() < allowed,
                    "dof {dof}, p {p}: quantile {x}, CDF {cdf}"
                );
            }
        }
    }

    /// Quantiles of the standard normal from tables (Abramowitz and Stegun
    /// 26.2; R's qnorm for the far tail).
    #[test]
    fn the_normal_quantile_matches_tabulated_values_and_inverts_the_cdf() {
        let table = [
            (0.5, 0.0),
            (0.8413447460685429, 1.0),
            (0.975, 1.959963984540054),
            (0.995, 2.5758293035489004),
            (1e-5, -4.264890793922825),
            (1e-20, -9.262340089798408),
        ];
        for (p, x) in table {
            let q = standard_normal_quantile(p);
            assert!((q - x).abs() <= 1e-13 * x.abs().max(1.0), "{p}: {q} vs {x}");
        }
        // The round trip through the CDF, over 30 decades of the tail.
        for k in 1..300 {
            let p = 10f64.powf(-(k as f64) / 10.0);
            let back = standard_normal_cdf(standard_normal_quantile(p));
            assert!((back / p - 1.0).abs() < 1e-13, "{p}: {back}");
        }
        assert_eq!(
            standard_normal_quantile(0.0).to_bits(),
            f64::NEG_INFINITY.to_bits()
        );
        assert!(standard_normal_quantile(1.5).is_nan());
    }

    #[test]
    fn truncated_normal_quantiles_stay_in_their_bounds_and_invert_the_cdf() {
        for (mu, sigma, low, high) in [
            (0.0, 1.0, -1.0, 2.0),
            (0.0, 1.0, 6.0, 9.0),    // deep in the upper tail
            (0.0, 1.0, -30.0, -8.0), // deep in the lower tail
            (5.0, 0.1, 0.0, 10.0),   // barely truncated
        ] {
            let m = Marginal::TruncatedNormal {
                mu,
                sigma,
                low,
                high,
            };
            m.check(0).unwrap();
            let mut last = low;
            for i in 1..100 {
                let p = i as f64 / 100.0;
                let x = m.quantile(p);
                assert!((low..=high).contains(&x) && x >= last, "{m:?} {p}: {x}");
                last = x;
                assert!((m.cdf(x) - p).abs() < 1e-9, "{m:?} {p}: cdf {}", m.cdf(x));
            }
        }
    }

    #[test]
    fn log_normal_quantiles_are_the_exponentials_of_normal_ones() {
        let (mu, sigma) = (-0.916, 0.5);
        let log = Marginal::LogNormal { mu, sigma };
        let normal = Marginal::Normal { mu, sigma };
        for p in [1e-6, 0.1, 0.5, 0.9, 1.0 - 1e-6] {
            assert!((log.quantile(p) - normal.quantile(p).exp()).abs() < 1e-15);
            assert!((log.cdf(log.quantile(p)) - p).abs() < 1e-12);
        }
        assert_eq!(log.transform(), Transform::Log);
        assert_eq!(log.cdf(-1.0).to_bits(), 0f64.to_bits());
        let (low, high) = normal.range();
        assert!((normal.cdf(low) - UNBOUNDED_TAIL).abs() < 1e-18);
        assert!((normal.cdf(high) - (1.0 - UNBOUNDED_TAIL)).abs() < 1e-15);
    }

    #[test]
    fn malformed_marginals_are_refused_with_the_reason() {
        for bad in [
            Marginal::Uniform {
                low: 1.0,
                high: 1.0,
            },
            Marginal::Normal {
                mu: 0.0,
                sigma: 0.0,
            },
            Marginal::LogNormal {
                mu: f64::NAN,
                sigma: 1.0,
            },
            Marginal::TruncatedNormal {
                mu: 0.0,
                sigma: 1.0,
                low: 40.0,
                high: 41.0,
            },
        ] {
            let e = bad.check(3).unwrap_err().to_string();
            assert!(e.contains("parameter 3"), "{e}");
        }
    }
}
