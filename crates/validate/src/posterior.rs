//! How far to trust a posterior's draws, read from records whose
//! parameters are known: simulation-based calibration (Talts et al.,
//! "Validating Bayesian inference algorithms with simulation-based
//! calibration", 2018) and the expected coverage of its regions.
//!
//! For each record, each parameter's true value is ranked among the
//! draws given the record; where the draws come from the exact posterior,
//! the rank is uniform over the records. The same holds of the joint
//! region of highest density: the true vector lies in the region of level
//! q on a share q of the records.

use serde::{Deserialize, Serialize};

use crate::error::{Result, ValidateError};

/// The levels whose coverage a [`PosteriorCalibration`] reports.
pub const COVERAGE_LEVELS: [f64; 3] = [0.5, 0.9, 0.95];

/// Draws of each record's posterior a validation ranks its truth among:
/// the ranks' resolution is 1/201.
pub const CALIBRATION_DRAWS: usize = 200;

/// A posterior's calibration on records of known parameters.
///
/// ```
/// use twostage_validate::PosteriorCalibration;
/// // Ranks spread evenly, the truth at every region level in turn: calibrated.
/// let n = 1000;
/// let ranks: Vec<Vec<f64>> = (0..n).map(|i| vec![(i as f64 + 0.5) / n as f64]).collect();
/// let levels: Vec<f64> = ranks.iter().map(|r| r[0]).collect();
/// let calibration = PosteriorCalibration::from_ranks(&ranks, &levels, 100)?;
/// assert!((calibration.joint[1] - 0.9).abs() < 0.002);
/// assert!((calibration.central[0][1] - 0.9).abs() < 0.002);
/// assert!(calibration.uniformity_p[0] > 0.99);
/// # Ok::<(), twostage_validate::ValidateError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorCalibration {
    /// Records scored.
    pub records: usize,
    /// Draws per record.
    pub draws: usize,
    /// The share of records whose whole parameter vector lies in the
    /// region of highest density of each [`COVERAGE_LEVELS`] level.
    pub joint: [f64; 3],
    /// Per parameter, the share of records whose value lies in the
    /// draws' central interval of each [`COVERAGE_LEVELS`] level.
    pub central: Vec<[f64; 3]>,
    /// Per parameter, the largest distance between the ranks' empirical
    /// distribution and the uniform (Kolmogorov-Smirnov).
    pub uniformity_distance: Vec<f64>,
    /// Per parameter, the probability of a distance at least as large were
    /// the ranks uniform (Kolmogorov's limiting distribution): small where
    /// the posterior is too narrow, too wide or off centre.
    pub uniformity_p: Vec<f64>,
}

impl PosteriorCalibration {
    /// The calibration of `ranks` (per record, per parameter, the share
    /// of its `draws` draws below the true value) and `levels` (per record,
    /// the share of the draws more probable than the true vector: the
    /// smallest region level that holds it).
    ///
    /// # Errors
    /// No record, records of different widths, or a share outside [0, 1].
    pub fn from_ranks(ranks: &[Vec<f64>], levels: &[f64], draws: usize) -> Result<Self> {
        let invalid = |why: String| Err(ValidateError::InvalidErrors(why));
        let records = ranks.len();
        if records == 0 || levels.len() != records {
            return invalid(format!(
                "{records} records' ranks and {} region levels: give one of each per record",
                levels.len()
            ));
        }
        let q = ranks[0].len();
        let outside = |v: f64| !(0.0..=1.0).contains(&v);
        if let Some(i) = ranks
            .iter()
            .position(|r| r.len() != q || r.iter().any(|&v| outside(v)))
        {
            return invalid(format!(
                "record {i}: ranks {:?}: give {q} shares in [0, 1]",
                ranks[i]
            ));
        }
        if let Some(i) = levels.iter().position(|&v| outside(v)) {
            return invalid(format!(
                "record {i}: region level {}: give a share in [0, 1]",
                levels[i]
            ));
        }
        let share = |hits: usize| hits as f64 / records as f64;
        let joint = COVERAGE_LEVELS.map(|q| share(levels.iter().filter(|&&l| l <= q).count()));
        let mut central = Vec::with_capacity(q);
        let (mut distance, mut p) = (Vec::with_capacity(q), Vec::with_capacity(q));
        for j in 0..q {
            let mut column: Vec<f64> = ranks.iter().map(|r| r[j]).collect();
            central.push(COVERAGE_LEVELS.map(|level| {
                share(
                    column
                        .iter()
                        .filter(|&&u| (u - 0.5).abs() <= level / 2.0)
                        .count(),
                )
            }));
            column.sort_by(f64::total_cmp);
            let d = column
                .iter()
                .enumerate()
                .map(|(i, &u)| {
                    let (below, at) = (i as f64 / records as f64, (i + 1) as f64 / records as f64);
                    (u - below).max(at - u)
                })
                .fold(0.0, f64::max);
            distance.push(d);
            p.push(kolmogorov_tail(d, records));
        }
        Ok(Self {
            records,
            draws,
            joint,
            central,
            uniformity_distance: distance,
            uniformity_p: p,
        })
    }
}

impl PosteriorCalibration {
    /// How far the draws can be trusted, in a validation report's style,
    /// parameter by parameter (`names`): the joint region's coverage, each
    /// parameter's central intervals' and its ranks' uniformity.
    ///
    /// ```
    /// use twostage_validate::PosteriorCalibration;
    /// let ranks: Vec<Vec<f64>> = (0..100).map(|i| vec![(i as f64 + 0.5) / 100.0]).collect();
    /// let levels: Vec<f64> = ranks.iter().map(|r| r[0]).collect();
    /// let words = PosteriorCalibration::from_ranks(&ranks, &levels, 200)?.describe(&["theta".into()]);
    /// assert!(words.contains("90% 0.900") && words.contains("uniform as far as these records tell"));
    /// # Ok::<(), twostage_validate::ValidateError>(())
    /// ```
    pub fn describe(&self, names: &[String]) -> String {
        let shares = |s: &[f64; 3]| {
            COVERAGE_LEVELS
                .iter()
                .zip(s)
                .map(|(level, share)| format!("{:.0}% {share:.3}", 100.0 * level))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut text = format!(
            "posterior ({} draws of each of the {} records): the region of highest density \
             holds the whole parameter vector at {}\n",
            self.draws,
            self.records,
            shares(&self.joint)
        );
        for (j, name) in names.iter().enumerate().take(self.central.len()) {
            let verdict = if self.uniformity_p[j] < 0.01 {
                "not uniform: the draws are off centre, too narrow or too wide"
            } else {
                "uniform as far as these records tell"
            };
            text.push_str(&format!(
                "  {name}  central intervals hold it at {}; its ranks among the draws: \
                 distance {:.3} from uniform (p {:.3}), {verdict}\n",
                shares(&self.central[j]),
                self.uniformity_distance[j],
                self.uniformity_p[j]
            ));
        }
        text
    }
}

/// `P(D_n >= d)` for the Kolmogorov-Smirnov distance of `n` uniform
/// draws, by the limiting distribution `Q(λ) = 2 Σ (−1)^(k−1) e^(−2k²λ²)`
/// at `λ = (√n + 0.12 + 0.11/√n) d` (Stephens' correction; Press et al.,
/// Numerical Recipes, 3rd ed., eq. 14.3.9).
fn kolmogorov_tail(d: f64, n: usize) -> f64 {
    let root = (n as f64).sqrt();
    let lambda = (root + 0.12 + 0.11 / root) * d;
    if lambda < 0.2 {
        return 1.0;
    }
    let (mut sum, mut sign) = (0.0, 1.0);
    for k in 1..=100u32 {
        let k = f64::from(k);
        let term = (-2.0 * k * k * lambda * lambda).exp();
        sum += sign * term;
        sign = -sign;
        if term < 1e-16 {
            break;
        }
    }
    (2.0 * sum).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::uniform_stream;

    /// Kolmogorov's tail at the textbook critical values: 1.358 at 5%,
    /// 1.628 at 1% (for large n, λ ≈ √n d).
    #[test]
    fn the_kolmogorov_tail_is_at_its_critical_values() {
        let n = 1_000_000;
        let at = |lambda: f64| kolmogorov_tail(lambda / (n as f64).sqrt(), n);
        assert!((at(1.3581) - 0.05).abs() < 2e-4, "{}", at(1.3581));
        assert!((at(1.6276) - 0.01).abs() < 1e-4, "{}", at(1.6276));
        assert!((kolmogorov_tail(0.0, 100) - 1.0).abs() < 1e-15);
    }

    /// Uniform ranks pass and cover at their levels; ranks of a posterior
    /// half as wide as it should be pile up at the ends and fail.
    #[test]
    fn a_too_narrow_posterior_fails_and_a_right_one_passes() {
        let mut uniform = uniform_stream(5);
        let n = 4000;
        let right: Vec<Vec<f64>> = (0..n).map(|_| vec![uniform(), uniform()]).collect();
        let levels: Vec<f64> = (0..n).map(|_| uniform()).collect();
        let calibrated = PosteriorCalibration::from_ranks(&right, &levels, 1000).unwrap();
        for j in 0..2 {
            assert!(calibrated.uniformity_p[j] > 0.01, "{calibrated:?}");
            for (l, level) in COVERAGE_LEVELS.iter().enumerate() {
                assert!((calibrated.central[j][l] - level).abs() < 0.025);
            }
        }
        // A normal posterior of half the true sd: the truth's rank is
        // Φ(2 z) for a standard normal z, by the inverse transform of u.
        let narrow: Vec<Vec<f64>> = right
            .iter()
            .map(|r| {
                r.iter()
                    .map(|&u| {
                        let z = inverse_normal(u);
                        0.5 * (1.0 + erf(2.0 * z / 2f64.sqrt()))
                    })
                    .collect()
            })
            .collect();
        let wrong = PosteriorCalibration::from_ranks(&narrow, &levels, 1000).unwrap();
        assert!(wrong.uniformity_p[0] < 1e-6, "{wrong:?}");
        // Its 90% interval holds the truth where |2z| < 1.645: |z| < 0.82,
        // 0.59 of the records.
        assert!((wrong.central[0][1] - 0.588).abs() < 0.03, "{wrong:?}");
        assert!(PosteriorCalibration::from_ranks(&[], &[], 10).is_err());
        assert!(PosteriorCalibration::from_ranks(&[vec![1.5]], &[0.5], 10).is_err());
        assert!(PosteriorCalibration::from_ranks(&[vec![0.5], vec![]], &[0.5, 0.5], 10).is_err());
    }

    /// The inverse of the standard normal's distribution function by
    /// bisection on [`erf`]: slow and plain, for tests.
    fn inverse_normal(u: f64) -> f64 {
        let (mut lo, mut hi) = (-10.0, 10.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if 0.5 * (1.0 + erf(mid / 2f64.sqrt())) < u {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// The error function (Abramowitz and Stegun 7.1.26, |error| < 1.5e-7).
    fn erf(x: f64) -> f64 {
        let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
        let poly = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        let y = 1.0 - poly * (-x * x).exp();
        if x < 0.0 { -y } else { y }
    }
}
