//! How far the records of one plant disagree beyond their noise. Each
//! record's own best fit lies, to first order, one Gauss-Newton step of
//! its own loss away from the joint estimate; under a model that makes
//! the records, those steps scatter as their sandwich covariances say.
//! A model that misses part of the plant has a best fit that moves with
//! each record's input: the steps then scatter more, and the joint
//! estimate's interval from the residuals alone (and each record's own)
//! is too narrow to hold between records. The excess is the random
//! effect of a meta-analysis, estimated by the method of moments of
//! DerSimonian and Laird ("Meta-analysis in clinical trials", Controlled
//! Clinical Trials 7, 1986), parameter by parameter.

use twostage_models::{chi_square_quantile, standard_normal_quantile};

/// The chance that a model which makes the records is said to be
/// mismatched by their scatter, over all its parameters.
const FALSE_ALARM: f64 = 0.01;

/// The variance between records beyond their own: of estimates `values`
/// whose own variances are `variances`, `tau^2 = max(0, (Q - (k - 1)) /
/// (S1 - S2 / S1))` with weights `w = 1 / v`, `S1 = sum w`, `S2 = sum w^2`
/// and `Q = sum w (y - ybar_w)^2` (DerSimonian and Laird's moment
/// estimate). Pairs with a variance that is not finite and positive, or a
/// value that is not finite, are left out; `None` with fewer than two left.
///
/// ```
/// use twostage_refine::between_record_variance;
/// // Two estimates 4 apart, each of variance 1: Q = 8, S1 = 2, S2 = 2,
/// // tau^2 = (8 - 1) / (2 - 1) = 7.
/// assert_eq!(between_record_variance(&[0.0, 4.0], &[1.0, 1.0]), Some(7.0));
/// // Estimates within their own noise: no variance between them.
/// assert_eq!(between_record_variance(&[0.0, 0.5], &[1.0, 1.0]), Some(0.0));
/// assert_eq!(between_record_variance(&[1.0], &[1.0]), None);
/// ```
pub fn between_record_variance(values: &[f64], variances: &[f64]) -> Option<f64> {
    Heterogeneity::of(values, variances).map(|h| h.tau2)
}

/// Cochran's `Q` of estimates with their own variances, the records that
/// count, and the moment estimate of the variance between them.
struct Heterogeneity {
    tau2: f64,
    q: f64,
    records: usize,
}

impl Heterogeneity {
    fn of(values: &[f64], variances: &[f64]) -> Option<Self> {
        let pairs: Vec<(f64, f64)> = values
            .iter()
            .zip(variances)
            .filter(|(y, v)| y.is_finite() && v.is_finite() && **v > 0.0)
            .map(|(y, v)| (*y, 1.0 / v))
            .collect();
        if pairs.len() < 2 {
            return None;
        }
        let s1: f64 = pairs.iter().map(|(_, w)| w).sum();
        let s2: f64 = pairs.iter().map(|(_, w)| w * w).sum();
        let mean = pairs.iter().map(|(y, w)| w * y).sum::<f64>() / s1;
        let q: f64 = pairs.iter().map(|(y, w)| w * (y - mean).powi(2)).sum();
        let excess = q - (pairs.len() - 1) as f64;
        Some(Self {
            tau2: (excess / (s1 - s2 / s1)).max(0.0),
            q,
            records: pairs.len(),
        })
    }
}

/// The scatter of a plant's records' own best fits about the joint
/// estimate, beyond their noise: see the module's documentation.
#[derive(Debug, Clone, PartialEq)]
pub struct BetweenRecords {
    /// Per parameter, the sd between records beyond their noise (`tau`,
    /// in the parameter's units): 0 where the records' own best fits
    /// scatter no more than their noise explains.
    pub sd: Vec<f64>,
    /// Per parameter, the median over the records of the sd of a record's
    /// own best fit from its noise alone.
    pub within_sd: Vec<f64>,
    /// Per parameter, the sd of the joint estimate under that scatter,
    /// `(sum_i 1 / (v_i + tau^2))^(-1/2)`.
    pub joint_sd: Vec<f64>,
    /// Per parameter, whether the scatter is beyond chance: Cochran's `Q`
    /// above its chi-square quantile of `records - 1` degrees of freedom
    /// at `1 - 0.01 / q` (a one-in-a-hundred false alarm for a model that
    /// makes the records, over all `q` parameters).
    pub beyond_chance: Vec<bool>,
    /// The records whose own step is known (the others' own losses do
    /// not determine every parameter).
    pub records: usize,
}

impl BetweenRecords {
    /// The scatter of records' own steps `(step, covariance)` (unit
    /// coordinates, covariance row-major q x q), in parameter units by the
    /// box's widths `span`; `None` with fewer than two steps.
    pub(crate) fn of_steps(steps: &[(Vec<f64>, Vec<f64>)], span: &[f64]) -> Option<Self> {
        if steps.len() < 2 {
            return None;
        }
        let q = span.len();
        let (mut sd, mut within_sd, mut joint_sd) = (vec![0.0; q], vec![0.0; q], vec![0.0; q]);
        let mut beyond_chance = vec![false; q];
        for j in 0..q {
            let values: Vec<f64> = steps.iter().map(|(s, _)| s[j] * span[j]).collect();
            let variances: Vec<f64> = steps
                .iter()
                .map(|(_, c)| c[j * q + j] * span[j] * span[j])
                .collect();
            let Heterogeneity {
                tau2,
                q: cochran,
                records,
            } = Heterogeneity::of(&values, &variances)?;
            sd[j] = tau2.sqrt();
            beyond_chance[j] =
                cochran > chi_square_quantile(1.0 - FALSE_ALARM / q as f64, records - 1);
            let mut own: Vec<f64> = variances.iter().map(|v| v.sqrt()).collect();
            own.sort_by(f64::total_cmp);
            within_sd[j] = own[own.len() / 2];
            let precision: f64 = variances.iter().map(|v| 1.0 / (v + tau2)).sum();
            joint_sd[j] = 1.0 / precision.sqrt();
        }
        Some(Self {
            sd,
            within_sd,
            joint_sd,
            beyond_chance,
            records: steps.len(),
        })
    }

    /// The same of a model of `q` parameters, these being those at
    /// `places`: the others (a record's own) scatter by nothing.
    pub(crate) fn of_parameters(self, places: &[usize], q: usize) -> Self {
        if places.len() == q {
            return self;
        }
        let spread = |values: &[f64]| {
            let mut whole = vec![0.0; q];
            for (&j, v) in places.iter().zip(values) {
                whole[j] = *v;
            }
            whole
        };
        let mut beyond_chance = vec![false; q];
        for (&j, b) in places.iter().zip(&self.beyond_chance) {
            beyond_chance[j] = *b;
        }
        Self {
            sd: spread(&self.sd),
            within_sd: spread(&self.within_sd),
            joint_sd: spread(&self.joint_sd),
            beyond_chance,
            records: self.records,
        }
    }

    /// The parameters whose scatter between records is beyond chance and
    /// exceeds a record's own sd from its noise: the model's mismatch, not
    /// the noise, sets their intervals' width.
    ///
    /// ```
    /// use twostage_refine::BetweenRecords;
    /// let between = BetweenRecords {
    ///     sd: vec![3.0, 0.0, 2.0], within_sd: vec![1.0, 1.0, 1.0], joint_sd: vec![1.0, 0.3, 0.8],
    ///     beyond_chance: vec![true, false, false], records: 10,
    /// };
    /// assert_eq!(between.mismatch_sets_width(), [true, false, false]);
    /// ```
    pub fn mismatch_sets_width(&self) -> Vec<bool> {
        self.sd
            .iter()
            .zip(&self.within_sd)
            .zip(&self.beyond_chance)
            .map(|((tau, own), beyond)| *beyond && tau > own)
            .collect()
    }

    /// A record's interval half-widths at level `1 - alpha` with the
    /// scatter between records added, `sqrt(w^2 + (z tau)^2)`: an interval
    /// of the plant's value, which the record's own best fit misses by the
    /// mismatch its input makes.
    ///
    /// ```
    /// use twostage_refine::BetweenRecords;
    /// let between = BetweenRecords { sd: vec![1.0], within_sd: vec![1.0], joint_sd: vec![0.5], beyond_chance: vec![true], records: 4 };
    /// let z = 1.6448536269514722;
    /// let widened = between.widen(&[z], 0.1);
    /// assert!((widened[0] - z * 2f64.sqrt()).abs() < 1e-9);
    /// ```
    pub fn widen(&self, half_widths: &[f64], alpha: f64) -> Vec<f64> {
        let z = standard_normal_quantile(1.0 - alpha / 2.0);
        half_widths
            .iter()
            .zip(&self.sd)
            .map(|(w, tau)| w.hypot(z * tau))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Many estimates with a known between variance: DerSimonian and
    /// Laird's estimate lands near it, and near zero without one.
    #[test]
    fn the_moment_estimate_finds_a_known_variance() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let k = 20_000;
        let variances: Vec<f64> = (0..k).map(|i| 0.5 + (i % 4) as f64 * 0.5).collect();
        for tau2 in [0.0, 1.5] {
            let values: Vec<f64> = variances
                .iter()
                .map(|v| 3.0 + (v + tau2).sqrt() * normal())
                .collect();
            let found = between_record_variance(&values, &variances).unwrap();
            assert!((found - tau2).abs() < 0.06, "{found} against {tau2}");
        }
    }

    #[test]
    fn steps_in_unit_coordinates_scale_by_the_box() {
        // Two parameters; the second's steps lie within their noise.
        let cov = vec![0.01, 0.0, 0.0, 0.01];
        let steps = vec![
            (vec![0.3, 0.01], cov.clone()),
            (vec![-0.3, -0.01], cov.clone()),
            (vec![0.0, 0.0], cov),
        ];
        let between = BetweenRecords::of_steps(&steps, &[10.0, 2.0]).unwrap();
        // Parameter 0 in its units: values 3, -3, 0 of variance 1 each:
        // Q = 18, S1 = 3, S2 = 3, tau^2 = 16 / 2 = 8.
        assert!((between.sd[0] - 8f64.sqrt()).abs() < 1e-12);
        assert_eq!(between.sd[1].to_bits(), 0.0f64.to_bits());
        assert!((between.within_sd[0] - 1.0).abs() < 1e-12);
        assert!((between.joint_sd[0] - (9.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((between.joint_sd[1] - 0.2 / 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(between.beyond_chance, [true, false]);
        assert_eq!(between.mismatch_sets_width(), [true, false]);
        assert!(BetweenRecords::of_steps(&steps[..1], &[1.0, 1.0]).is_none());
    }
}
