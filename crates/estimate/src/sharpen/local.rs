//! The local likelihood a record's draws are sharpened by: stage 1's
//! features of runs of the model near the record's posterior, regressed
//! on the parameters' unbounded values, read as a Gaussian whose mean is
//! linear in them (a synthetic likelihood, Wood 2010, with a local linear
//! mean), and its product with the prior drawn exactly by rejection.

use rand::Rng;
use twostage_kernels::cholesky::{
    PivotRule, RANK_TOLERANCE, cholesky_in_place, solve_cholesky_in_place, solve_lower_in_place,
    solve_lower_transposed_in_place,
};
use twostage_kernels::random::standard_normals;
use twostage_kernels::random::unit_uniform;
use twostage_models::Marginal;

/// A Gaussian over the unbounded parameters: its mean and the lower
/// Cholesky factor `L` of its precision (`P = L L'`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Gaussian {
    pub(crate) mean: Vec<f64>,
    precision_factor: Vec<f64>,
}

impl Gaussian {
    /// A draw: `mean + L'^-1 n` for standard normal `n`, whose covariance
    /// is `(L L')^-1`.
    pub(crate) fn draw(&self, rng: &mut impl Rng, out: &mut [f64]) {
        let q = self.mean.len();
        standard_normals(&mut || rng.next_u64(), out);
        solve_lower_transposed_in_place(&self.precision_factor, q, out);
        for (v, m) in out.iter_mut().zip(&self.mean) {
            *v += m;
        }
    }

    /// The log density at `z`, up to a constant: `-|L' (z - mean)|^2 / 2`.
    pub(crate) fn log_density(&self, z: &[f64]) -> f64 {
        let q = self.mean.len();
        (0..q)
            .map(|i| {
                let v: f64 = (i..q)
                    .map(|j| self.precision_factor[j * q + i] * (z[j] - self.mean[j]))
                    .sum();
                v * v
            })
            .sum::<f64>()
            * -0.5
    }

    /// The Gaussian of `draws` (rows of `q` values): their mean and
    /// covariance, the covariance's spread widened `widen` times.
    pub(crate) fn of_draws(draws: &[f64], q: usize, widen: f64) -> Result<Self, String> {
        let n = draws.len() / q.max(1);
        if n <= q {
            return Err(format!(
                "{n} draws cannot give the spread of {q} parameters"
            ));
        }
        let mut mean = vec![0.0; q];
        for row in draws.chunks_exact(q) {
            for (m, v) in mean.iter_mut().zip(row) {
                *m += v / n as f64;
            }
        }
        let mut covariance = vec![0.0; q * q];
        for row in draws.chunks_exact(q) {
            for a in 0..q {
                for b in 0..q {
                    covariance[a * q + b] +=
                        (row[a] - mean[a]) * (row[b] - mean[b]) * widen * widen / (n - 1) as f64;
                }
            }
        }
        Ok(Self {
            precision_factor: precision_factor_of_covariance(covariance, q)?,
            mean,
        })
    }
}

/// `L` with `L L' = C^-1` for the covariance `C` (row-major `q x q`).
fn precision_factor_of_covariance(mut covariance: Vec<f64>, q: usize) -> Result<Vec<f64>, String> {
    cholesky_in_place(&mut covariance, q, PivotRule::RelativeToLargest(1e-12)).map_err(|e| {
        format!("the draws do not spread in every parameter ({e}): a parameter does not vary")
    })?;
    // C = K K' gives C^-1 = K'^-1 K^-1; its columns solved one at a time.
    let mut precision = vec![0.0; q * q];
    for j in 0..q {
        let mut e = vec![0.0; q];
        e[j] = 1.0;
        solve_cholesky_in_place(&covariance, q, &mut e);
        for i in 0..q {
            precision[i * q + j] = e[i];
        }
    }
    cholesky_in_place(&mut precision, q, PivotRule::Positive)
        .map_err(|e| format!("the draws' precision is not positive definite ({e})"))?;
    Ok(precision)
}

/// Stage 1's features of runs regressed on regressors of the runs'
/// parameters by least squares, `s = s0 + B (x - x0) + e`, with `e` of the
/// residuals' covariance `S = K K'` (its correlations shrunk). Features
/// that no run moves (a sample that is always zero, say) are left out:
/// `moved` names the ones kept.
pub(crate) struct Regression {
    /// The regressors' mean `x0`.
    pub(crate) regressors_mean: Vec<f64>,
    /// The kept features' mean `s0`.
    pub(crate) features_mean: Vec<f64>,
    /// `B`, row after row of the kept features, `r` slopes each.
    pub(crate) slopes: Vec<f64>,
    /// The lower Cholesky factor `K` of the residuals' covariance.
    pub(crate) noise_factor: Vec<f64>,
    /// The features kept, by index.
    pub(crate) moved: Vec<usize>,
}

impl Regression {
    /// The fit of `features` (rows of `p`) on `regressors` (rows of `r`),
    /// one row a run.
    ///
    /// # Errors
    /// Fewer runs than the fit needs, regressors that do not vary apart,
    /// or residuals collinear across features (more features than runs can
    /// spread).
    pub(crate) fn fit(
        regressors: &[f64],
        r: usize,
        features: &[f64],
        p: usize,
    ) -> Result<Self, String> {
        let m = regressors.len() / r.max(1);
        if features.len() != m * p {
            return Err(format!(
                "{} feature values for {m} runs of {p} features",
                features.len()
            ));
        }
        let mean_of = |values: &[f64], width: usize| -> Vec<f64> {
            let mut mean = vec![0.0; width];
            for row in values.chunks_exact(width) {
                for (s, v) in mean.iter_mut().zip(row) {
                    *s += v / m as f64;
                }
            }
            mean
        };
        let x0 = mean_of(regressors, r);
        let all_means = mean_of(features, p);
        let moved: Vec<usize> = (0..p)
            .filter(|&k| {
                features
                    .chunks_exact(p)
                    .any(|row| (row[k] - all_means[k]).abs() > 1e-12 * (1.0 + all_means[k].abs()))
            })
            .collect();
        let kept = moved.len();
        if m < r + kept + 2 {
            return Err(format!(
                "{m} runs for {r} regressors and {kept} features that vary: at least {} needed",
                r + kept + 2
            ));
        }
        // Normal equations of the centred regression: G = Xc' Xc, B' = G^-1 Xc' Sc.
        let mut gram = vec![0.0; r * r];
        let mut cross = vec![0.0; r * kept];
        for (x, s) in regressors.chunks_exact(r).zip(features.chunks_exact(p)) {
            for a in 0..r {
                let da = x[a] - x0[a];
                for b in 0..r {
                    gram[a * r + b] += da * (x[b] - x0[b]);
                }
                for (c, &k) in moved.iter().enumerate() {
                    cross[a * kept + c] += da * (s[k] - all_means[k]);
                }
            }
        }
        cholesky_in_place(&mut gram, r, PivotRule::Angle(RANK_TOLERANCE))
            .map_err(|e| format!("the runs do not move every parameter apart ({e})"))?;
        let mut slopes = vec![0.0; kept * r];
        for c in 0..kept {
            let mut column: Vec<f64> = (0..r).map(|a| cross[a * kept + c]).collect();
            solve_cholesky_in_place(&gram, r, &mut column);
            slopes[c * r..(c + 1) * r].copy_from_slice(&column);
        }
        let mut residuals = Vec::with_capacity(m * kept);
        for (x, s) in regressors.chunks_exact(r).zip(features.chunks_exact(p)) {
            for (c, &k) in moved.iter().enumerate() {
                let fitted: f64 = (0..r).map(|a| slopes[c * r + a] * (x[a] - x0[a])).sum();
                residuals.push(s[k] - all_means[k] - fitted);
            }
        }
        let mut covariance = shrunk_covariance(&residuals, kept, m - r - 1);
        cholesky_in_place(&mut covariance, kept, PivotRule::RelativeToLargest(1e-12)).map_err(
            |e| format!("the features' noise is collinear ({e}): more runs, or fewer features"),
        )?;
        Ok(Self {
            regressors_mean: x0,
            features_mean: moved.iter().map(|&k| all_means[k]).collect(),
            slopes,
            noise_factor: covariance,
            moved,
        })
    }

    /// The combinations `B' S^-1` of the `p` features (zero on those left
    /// out), one a regressor: where the features' mean is linear in the
    /// regressors with Gaussian noise of covariance `S`, they keep all the
    /// features tell of the regressors ([`Summary`]).
    pub(crate) fn combinations(&self, p: usize) -> Summary {
        let kept = self.moved.len();
        let r = self.regressors_mean.len();
        let whitened = self.whitened_slopes();
        let mut weights = vec![0.0; r * p];
        for a in 0..r {
            let mut row: Vec<f64> = (0..kept).map(|c| whitened[c * r + a]).collect();
            solve_lower_transposed_in_place(&self.noise_factor, kept, &mut row);
            for (c, &k) in self.moved.iter().enumerate() {
                weights[a * p + k] = row[c];
            }
        }
        Summary { weights, p }
    }

    /// `K^-1 B`, rows of the kept features: the slopes in units of the
    /// noise.
    pub(crate) fn whitened_slopes(&self) -> Vec<f64> {
        let kept = self.moved.len();
        let r = self.regressors_mean.len();
        let mut whitened = vec![0.0; kept * r];
        for a in 0..r {
            let mut column: Vec<f64> = (0..kept).map(|c| self.slopes[c * r + a]).collect();
            solve_lower_in_place(&self.noise_factor[..], kept, &mut column);
            for c in 0..kept {
                whitened[c * r + a] = column[c];
            }
        }
        whitened
    }

    /// `K^-1 (observed - s0)` over the kept features: the record's gap to
    /// the runs' mean, whitened.
    pub(crate) fn whitened_gap(&self, observed: &[f64]) -> Vec<f64> {
        let mut gap: Vec<f64> = self
            .moved
            .iter()
            .zip(&self.features_mean)
            .map(|(&k, s0)| observed[k] - s0)
            .collect();
        solve_lower_in_place(&self.noise_factor[..], self.moved.len(), &mut gap);
        gap
    }
}

/// The likelihood of the `observed` features as a Gaussian over the
/// unbounded parameters: the features of the runs (`features`, rows of
/// `p`) regressed on the runs' parameters (`at`, rows of `q`),
/// `s = s0 + D (z - z0) + e` with `e` of covariance `S` ([`Regression`]);
/// its precision `D' S^-1 D` and the `z` that best explains `observed`.
///
/// # Errors
/// Those of [`Regression::fit`], an `observed` of another width, and
/// features that carry no information on some parameter.
pub(crate) fn local_likelihood(
    at: &[f64],
    q: usize,
    features: &[f64],
    p: usize,
    observed: &[f64],
) -> Result<Gaussian, String> {
    if observed.len() != p {
        return Err(format!("{} observed features for {p}", observed.len()));
    }
    let fit = Regression::fit(at, q, features, p)?;
    let kept = fit.moved.len();
    // Whitened: W = K^-1 D (kept x q), v = K^-1 (observed - s0).
    let whitened = fit.whitened_slopes();
    let gap = fit.whitened_gap(observed);
    let mut precision = vec![0.0; q * q];
    let mut toward = vec![0.0; q];
    for c in 0..kept {
        for a in 0..q {
            toward[a] += whitened[c * q + a] * gap[c];
            for b in 0..q {
                precision[a * q + b] += whitened[c * q + a] * whitened[c * q + b];
            }
        }
    }
    cholesky_in_place(&mut precision, q, PivotRule::Angle(RANK_TOLERANCE)).map_err(|e| {
        format!("the features carry no information on some parameter near the record ({e})")
    })?;
    solve_cholesky_in_place(&precision, q, &mut toward);
    let mean = fit
        .regressors_mean
        .iter()
        .zip(&toward)
        .map(|(z, t)| z + t)
        .collect();
    Ok(Gaussian {
        mean,
        precision_factor: precision,
    })
}

/// The covariance of `residuals` (rows of `p`, `dof` degrees of freedom
/// left by the fit), its correlations shrunk toward zero by the
/// intensity of Schäfer and Strimmer (2005, Stat. Appl. Genet. Mol. Biol.
/// 4(1), target D): the sum of the correlations' estimated variances over
/// the sum of their squares, at most 1. With many features and few runs
/// the sample correlations' noise would otherwise enter the likelihood's
/// weights; with few features and many runs the intensity is near 0.
pub(super) fn shrunk_covariance(residuals: &[f64], p: usize, dof: usize) -> Vec<f64> {
    let m = residuals.len() / p.max(1);
    let sd: Vec<f64> = (0..p)
        .map(|a| {
            let sum: f64 = residuals.chunks_exact(p).map(|r| r[a] * r[a]).sum();
            (sum / dof.max(1) as f64).sqrt()
        })
        .collect();
    let mut correlation = vec![0.0; p * p];
    let mut spread = vec![0.0; p * p];
    for r in residuals.chunks_exact(p) {
        for a in 0..p {
            for b in 0..a {
                let w = r[a] * r[b] / (sd[a] * sd[b]);
                correlation[a * p + b] += w;
                spread[a * p + b] += w * w;
            }
        }
    }
    let (mut variance, mut square) = (0.0, 0.0);
    for a in 0..p {
        for b in 0..a {
            let mean = correlation[a * p + b] / m as f64;
            // sum (w - mean)^2 = sum w^2 - m mean^2, scaled as the paper's.
            let var_w = (spread[a * p + b] - m as f64 * mean * mean).max(0.0);
            let r = correlation[a * p + b] / dof.max(1) as f64;
            variance += var_w * m as f64 / ((m - 1).max(1) as f64).powi(3);
            square += r * r;
        }
    }
    let intensity = if square > 0.0 {
        (variance / square).min(1.0)
    } else {
        1.0
    };
    let mut covariance = vec![0.0; p * p];
    for a in 0..p {
        covariance[a * p + a] = sd[a] * sd[a];
        for b in 0..a {
            let r = (1.0 - intensity) * correlation[a * p + b] / dof.max(1) as f64;
            covariance[a * p + b] = r * sd[a] * sd[b];
            covariance[b * p + a] = covariance[a * p + b];
        }
    }
    covariance
}

/// `r` linear combinations of `p` features, `B' S^-1` of a local fit
/// ([`Regression::combinations`]): where the features' mean is linear in
/// the fit's `r` regressors with Gaussian noise, they keep all the
/// features tell of them, so a later round fits its likelihood on `r`
/// numbers instead of `p` (its slopes and noise then need runs in
/// proportion to `r`, not `p`). Combinations a little off those of the
/// exact likelihood lose a little information, and widen the posterior,
/// never narrow it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Summary {
    weights: Vec<f64>,
    p: usize,
}

impl Summary {
    /// How many combinations.
    pub(crate) fn len(&self) -> usize {
        self.weights.len() / self.p.max(1)
    }

    /// The combinations of `features` (rows of `p`), rows of [`Self::len`].
    pub(crate) fn of(&self, features: &[f64]) -> Vec<f64> {
        let q = self.len();
        features
            .chunks_exact(self.p.max(1))
            .flat_map(|s| {
                self.weights
                    .chunks_exact(self.p.max(1))
                    .map(|w| w.iter().zip(s).map(|(a, b)| a * b).sum::<f64>())
                    .collect::<Vec<_>>()
            })
            .take(features.len() / self.p.max(1) * q)
            .collect()
    }
}

/// The most candidates drawn per draw kept before the prior is said to
/// leave no room for the likelihood.
const MOST_CANDIDATES_PER_DRAW: usize = 10_000;

/// `n` draws (rows of unbounded values) of the posterior `prior x
/// likelihood`, the likelihood a Gaussian: candidates from it, each kept
/// with probability its prior density over the largest that density can
/// be (exact rejection sampling).
///
/// # Errors
/// The likelihood lies where the prior has almost no mass (fewer than
/// one candidate in [`MOST_CANDIDATES_PER_DRAW`] kept).
pub(crate) fn draw_with_prior(
    likelihood: &Gaussian,
    prior: &[Marginal],
    n: usize,
    rng: &mut impl Rng,
) -> Result<Vec<f64>, String> {
    let q = prior.len();
    let peak: f64 = prior.iter().map(Marginal::unbounded_log_density_peak).sum();
    let mut draws = Vec::with_capacity(n * q);
    let mut candidate = vec![0.0; q];
    let mut tried = 0usize;
    while draws.len() < n * q {
        if tried >= MOST_CANDIDATES_PER_DRAW * n.max(1) {
            return Err(format!(
                "{} of {tried} candidates kept: the record's likelihood lies where the prior has \
                 almost no mass",
                draws.len() / q.max(1)
            ));
        }
        tried += 1;
        likelihood.draw(rng, &mut candidate);
        let log_prior: f64 = prior
            .iter()
            .zip(&candidate)
            .map(|(marginal, z)| marginal.unbounded_log_density(*z))
            .sum();
        if unit_uniform(rng.next_u64()).ln() < log_prior - peak {
            draws.extend_from_slice(&candidate);
        }
    }
    Ok(draws)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
        let mut one = [0.0];
        standard_normals(&mut || rng.next_u64(), &mut one);
        one[0]
    }

    /// Features linear in two parameters with correlated Gaussian noise:
    /// the fitted likelihood's mean and precision against the closed form
    /// `P = D' S^-1 D`, `mean = P^-1 D' S^-1 (s - c)`, computed by hand
    /// for D = [[1, 0], [1, 1], [0, 2]], S = diag(0.01, 0.04, 0.09).
    #[test]
    fn the_local_likelihood_of_a_linear_model_is_its_closed_form() {
        let slopes = [[1.0, 0.0], [1.0, 1.0], [0.0, 2.0]];
        let noise_sd = [0.1, 0.2, 0.3];
        let offset = [0.5, -1.0, 2.0];
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let m = 200_000;
        let (mut at, mut features) = (Vec::new(), Vec::new());
        for _ in 0..m {
            let z = [standard_normal(&mut rng), standard_normal(&mut rng)];
            at.extend_from_slice(&z);
            for k in 0..3 {
                let mean = offset[k] + slopes[k][0] * z[0] + slopes[k][1] * z[1];
                features.push(mean + noise_sd[k] * standard_normal(&mut rng));
            }
        }
        let truth = [0.3, -0.2];
        let observed: Vec<f64> = (0..3)
            .map(|k| offset[k] + slopes[k][0] * truth[0] + slopes[k][1] * truth[1])
            .collect();
        let fitted = local_likelihood(&at, 2, &features, 3, &observed).expect("a fit");
        // The combinations are D' S^-1, by hand.
        let combinations = Regression::fit(&at, 2, &features, 3)
            .expect("a fit")
            .combinations(3);
        let weights = [100.0, 25.0, 0.0, 0.0, 25.0, 2.0 / 0.09];
        for (got, want) in combinations.weights.iter().zip(weights) {
            assert!(
                (got - want).abs() < 0.02 * (1.0 + want),
                "{:?}",
                combinations.weights
            );
        }
        // P = [[1/0.01 + 1/0.04, 1/0.04], [1/0.04, 1/0.04 + 4/0.09]].
        let p = [125.0, 25.0, 25.0, 25.0 + 4.0 / 0.09];
        let l = &fitted.precision_factor;
        let back = [
            l[0] * l[0],
            l[0] * l[2],
            l[2] * l[0],
            l[2] * l[2] + l[3] * l[3],
        ];
        for (got, want) in back.iter().zip(p) {
            assert!((got / want - 1.0).abs() < 0.01, "{back:?} against {p:?}");
        }
        for (got, want) in fitted.mean.iter().zip(truth) {
            assert!((got - want).abs() < 2e-3, "{:?}", fitted.mean);
        }
    }

    /// Independent residuals: the sample correlations are noise, shrunk
    /// nearly away; two residuals that share most of their noise keep
    /// their correlation (0.64, by construction) almost whole.
    #[test]
    fn correlations_are_shrunk_where_they_are_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let m = 4000;
        let independent: Vec<f64> = (0..m * 3).map(|_| standard_normal(&mut rng)).collect();
        let c = shrunk_covariance(&independent, 3, m);
        assert!(
            c[1].abs() < 0.01 && c[2].abs() < 0.01 && c[5].abs() < 0.01,
            "{c:?}"
        );
        assert!((c[0] - 1.0).abs() < 0.06, "{c:?}");
        let shared: Vec<f64> = (0..m)
            .flat_map(|_| {
                let common = standard_normal(&mut rng);
                let own = [standard_normal(&mut rng), standard_normal(&mut rng)];
                [0.8 * common + 0.6 * own[0], 0.8 * common + 0.6 * own[1]]
            })
            .collect();
        let c = shrunk_covariance(&shared, 2, m);
        let r = c[2] / (c[0] * c[3]).sqrt();
        assert!((r - 0.64).abs() < 0.03, "{r}");
    }

    /// A normal likelihood times a normal prior is the normal of summed
    /// precisions: N(1, 0.5^2) times a prior N(0, 1) has mean 0.8 and
    /// variance 0.2; the rejection sampler's draws say the same.
    #[test]
    fn draws_with_the_prior_are_the_product_of_two_normals() {
        let likelihood = Gaussian {
            mean: vec![1.0],
            precision_factor: vec![2.0],
        };
        let prior = [Marginal::Normal {
            mu: 0.0,
            sigma: 1.0,
        }];
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 200_000;
        let draws = draw_with_prior(&likelihood, &prior, n, &mut rng).expect("draws");
        let mean = draws.iter().sum::<f64>() / n as f64;
        let variance = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n as f64;
        assert!((mean - 0.8).abs() < 0.005, "{mean}");
        assert!((variance - 0.2).abs() < 0.003, "{variance}");
    }

    /// The Gaussian of draws widened twice has four times their variance,
    /// and draws from it have that spread.
    #[test]
    fn a_gaussian_of_draws_widens_their_spread() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let draws: Vec<f64> = (0..100_000)
            .flat_map(|_| {
                let a = standard_normal(&mut rng);
                [1.0 + a, 2.0 * a + 0.5 * standard_normal(&mut rng)]
            })
            .collect();
        let wide = Gaussian::of_draws(&draws, 2, 2.0).expect("spread");
        let mut out = [0.0; 2];
        let n = 100_000;
        let (mut s0, mut s1, mut s01) = (0.0, 0.0, 0.0);
        for _ in 0..n {
            wide.draw(&mut rng, &mut out);
            s0 += (out[0] - 1.0).powi(2);
            s1 += out[1].powi(2);
            s01 += (out[0] - 1.0) * out[1];
        }
        let n = n as f64;
        assert!((s0 / n - 4.0).abs() < 0.1, "{}", s0 / n);
        assert!((s1 / n - 4.0 * 4.25).abs() < 0.4, "{}", s1 / n);
        assert!((s01 / n - 8.0).abs() < 0.2, "{}", s01 / n);
        assert!(Gaussian::of_draws(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], 2, 1.0).is_err());
    }
}
