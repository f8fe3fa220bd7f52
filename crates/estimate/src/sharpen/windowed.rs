//! The last round's likelihood where the features' mean bends faster than
//! one quadratic can follow over the region the runs cover (the
//! benchmark's, which holds `sin(50 theta^2)`, say): the mean at each point
//! fitted by a quadratic over the runs in a window around it, weighted by
//! their distance (locally weighted regression, Cleveland 1979), the
//! window's width chosen by how well it predicts each run's features from
//! the other runs (leave-one-out). Where one quadratic over the whole
//! region predicts about as well, no window is chosen and the last round
//! stays [`super::curved::Curved`].

use twostage_kernels::cholesky::{
    PivotRule, RANK_TOLERANCE, cholesky_in_place, solve_cholesky_in_place, solve_lower_in_place,
};

use super::curved::{LastRoundLikelihood, quadratic_design, quadratic_regressors, regressor_count};
use super::local::{Regression, shrunk_covariance};

/// Window widths tried, in units of the runs' spread, widest first.
const WIDTHS: [f64; 4] = [2.0, 1.0, 0.5, 0.3];
/// The share by which a window must cut the features' leave-one-out
/// prediction error of one quadratic over the whole region to be chosen
/// (the leave-one-out error already counts a window's noisier fit; the
/// margin keeps one quadratic's combinations where the two are alike).
const WINDOW_GAIN: f64 = 0.02;
/// The most runs whose features the widths are scored on.
const SCORED_RUNS: usize = 400;
/// A window's fit is made where it holds at least this many runs a
/// regressor.
const RUNS_PER_REGRESSOR: usize = 3;
/// A point's mean is read from the fit around the nearest run if that
/// run lies within this share of the window's width, else the point is
/// beyond the runs.
const NEAREST_RUN: f64 = 0.25;

/// The features' likelihood with a mean fitted in a window around each
/// point and Gaussian noise of the covariance its leave-one-out residuals
/// have.
pub(crate) struct Windowed {
    centre: Vec<f64>,
    scale: Vec<f64>,
    runs: Runs,
    width: f64,
    /// The quadratic fitted around each run ([`Runs::local_fit`]), none
    /// where its window holds too few runs: a point's mean is read from
    /// the nearest run's, as exact as a fit around the point itself where
    /// the runs lie close, and a fit a run instead of one a candidate.
    fits: Vec<Option<Vec<f64>>>,
    /// The lower Cholesky factor of the noise's covariance.
    noise_factor: Vec<f64>,
    /// The record's features, those the runs move.
    observed: Vec<f64>,
}

/// Runs in units of their spread, sorted by the first parameter (a
/// window's runs then lie in one stretch), with the features they move.
struct Runs {
    q: usize,
    /// Rows of `q`.
    points: Vec<f64>,
    /// The first parameter of each run, ascending.
    firsts: Vec<f64>,
    /// Rows of `kept`.
    features: Vec<f64>,
    kept: usize,
    /// Where each run stood among the runs as given.
    given: Vec<usize>,
}

impl Windowed {
    /// The windowed fit of the runs' `features` (rows of `p`) at their
    /// unbounded parameters `at` (rows of `q`), read at the record's
    /// `observed` features, if a window predicts the runs' features better
    /// than one quadratic over them all; `None` if not, or where the fit
    /// of one quadratic, which the windows are measured against, cannot
    /// be made.
    pub(crate) fn choose(
        at: &[f64],
        q: usize,
        features: &[f64],
        p: usize,
        observed: &[f64],
    ) -> Option<Self> {
        if observed.len() != p {
            return None;
        }
        let design = quadratic_design(at, q).ok()?;
        let whole = Regression::fit(&design.regressors, regressor_count(q), features, p).ok()?;
        let m = at.len() / q;
        let kept = whole.moved.len();
        let mut points = Vec::with_capacity(m * q);
        let mut kept_features = Vec::with_capacity(m * kept);
        let mut order: Vec<usize> = (0..m).collect();
        let scaled = |i: usize, a: usize| (at[i * q + a] - design.centre[a]) / design.scale[a];
        order.sort_by(|&i, &j| scaled(i, 0).total_cmp(&scaled(j, 0)));
        for &i in &order {
            points.extend((0..q).map(|a| scaled(i, a)));
            kept_features.extend(whole.moved.iter().map(|&k| features[i * p + k]));
        }
        let runs = Runs {
            q,
            firsts: points.iter().step_by(q).copied().collect(),
            points,
            features: kept_features,
            kept,
            given: order,
        };
        // Scored: runs where the posterior lies (the runs are spread 1.5
        // times wider), the first of them as given (the runs are drawn
        // independently).
        let mut scored: Vec<usize> = (0..m)
            .filter(|&s| runs.point(s).iter().map(|x| x * x).sum::<f64>() <= 2.25 * q as f64)
            .collect();
        scored.sort_by_key(|&s| runs.given[s]);
        scored.truncate(SCORED_RUNS);
        let whitened_error = |residuals: &[f64]| -> f64 {
            residuals
                .chunks_exact(kept)
                .map(|r| {
                    let mut r = r.to_vec();
                    solve_lower_in_place(&whole.noise_factor[..], kept, &mut r);
                    r.iter().map(|v| v * v).sum::<f64>()
                })
                .sum()
        };
        let whole_error = whitened_error(&runs.left_out_residuals(&scored, f64::INFINITY)?);
        let (error, width, residuals) = WIDTHS
            .iter()
            .filter_map(|&width| {
                let residuals = runs.left_out_residuals(&scored, width)?;
                Some((whitened_error(&residuals), width, residuals))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        if error >= (1.0 - WINDOW_GAIN) * whole_error {
            return None;
        }
        let mut noise_factor = shrunk_covariance(&residuals, kept, scored.len());
        cholesky_in_place(&mut noise_factor, kept, PivotRule::RelativeToLargest(1e-12)).ok()?;
        let fits = (0..m)
            .map(|s| {
                let mut fit = vec![0.0; (1 + regressor_count(q)) * kept];
                runs.local_fit(runs.point(s), width, None, &mut fit)
                    .then_some(fit)
            })
            .collect();
        Some(Self {
            fits,
            centre: design.centre,
            scale: design.scale,
            width,
            noise_factor,
            observed: whole.moved.iter().map(|&k| observed[k]).collect(),
            runs,
        })
    }

    /// The window's width, in units of the runs' spread.
    #[cfg(test)]
    pub(crate) fn width(&self) -> f64 {
        self.width
    }
}

impl LastRoundLikelihood for Windowed {
    /// `-|K^-1 (observed - s(z))|^2 / 2`, `s(z)` the window's fit at `z`;
    /// minus infinity where the window holds too few runs to fit.
    fn log_likelihood(&self, z: &[f64], scratch: &mut Vec<f64>) -> f64 {
        let (q, kept) = (self.runs.q, self.runs.kept);
        let r = 1 + regressor_count(q);
        let point: Vec<f64> = z
            .iter()
            .zip(&self.centre)
            .zip(&self.scale)
            .map(|((v, c), s)| (v - c) / s)
            .collect();
        let (s, squared) = self.runs.nearest(&point);
        let Some(Some(fit)) = self.fits.get(s) else {
            return f64::NEG_INFINITY;
        };
        if squared > (NEAREST_RUN * self.width).powi(2) {
            return f64::NEG_INFINITY;
        }
        scratch.resize(r + kept, 0.0);
        let (row, gap) = scratch.split_at_mut(r);
        row[0] = 1.0;
        quadratic_regressors(
            &point,
            self.runs.point(s),
            &vec![self.width; q],
            &mut row[1..],
        );
        for (k, g) in gap.iter_mut().enumerate() {
            let fitted: f64 = (0..r).map(|a| fit[a * kept + k] * row[a]).sum();
            *g = self.observed[k] - fitted;
        }
        solve_lower_in_place(&self.noise_factor[..], kept, gap);
        -0.5 * gap.iter().map(|v| v * v).sum::<f64>()
    }
}

impl Runs {
    fn point(&self, s: usize) -> &[f64] {
        &self.points[s * self.q..(s + 1) * self.q]
    }

    /// Each `scored` run's features less the window's fit at its point
    /// from the other runs (rows of `kept`); `None` where a window holds
    /// too few runs.
    fn left_out_residuals(&self, scored: &[usize], width: f64) -> Option<Vec<f64>> {
        let kept = self.kept;
        let mut residuals = vec![0.0; scored.len() * kept];
        for (&s, row) in scored.iter().zip(residuals.chunks_exact_mut(kept)) {
            if !self.fitted_mean(self.point(s), width, Some(s), row) {
                return None;
            }
            for (r, f) in row.iter_mut().zip(&self.features[s * kept..(s + 1) * kept]) {
                *r = f - *r;
            }
        }
        Some(residuals)
    }

    /// The features' mean at `point` fitted by a quadratic in the
    /// deviations from it over the runs within `width` (all runs, equally
    /// weighted, for an infinite width), each weighted by the tricube of
    /// its distance over the width, run `skip` left out: the intercept of
    /// [`Runs::local_fit`].
    fn fitted_mean(
        &self,
        point: &[f64],
        width: f64,
        skip: Option<usize>,
        mean: &mut [f64],
    ) -> bool {
        let mut coefficients = vec![0.0; (1 + regressor_count(self.q)) * self.kept];
        if !self.local_fit(point, width, skip, &mut coefficients) {
            return false;
        }
        mean.copy_from_slice(&coefficients[..self.kept]);
        true
    }

    /// The quadratic fitted around `point` ([`Runs::fitted_mean`]): its
    /// coefficients on `1`, the deviations in units of the width and their
    /// products ([`quadratic_regressors`]), one row of `kept` a regressor;
    /// false where the window's runs do not fix a quadratic.
    fn local_fit(
        &self,
        point: &[f64],
        width: f64,
        skip: Option<usize>,
        coefficients: &mut [f64],
    ) -> bool {
        let (q, kept) = (self.q, self.kept);
        let r = 1 + regressor_count(q);
        let units = vec![if width.is_finite() { width } else { 1.0 }; q];
        let (lo, hi) = if width.is_finite() {
            (
                self.firsts.partition_point(|&x| x < point[0] - width),
                self.firsts.partition_point(|&x| x <= point[0] + width),
            )
        } else {
            (0, self.firsts.len())
        };
        let mut row = vec![0.0; r];
        let mut gram = vec![0.0; r * r];
        coefficients.fill(0.0);
        let mut inside = 0;
        for s in lo..hi {
            let x = self.point(s);
            let weight = tricube(x, point, width);
            if weight <= 0.0 || Some(s) == skip {
                continue;
            }
            inside += 1;
            row[0] = 1.0;
            quadratic_regressors(x, point, &units, &mut row[1..]);
            let features = &self.features[s * kept..(s + 1) * kept];
            for a in 0..r {
                for b in 0..=a {
                    gram[a * r + b] += weight * row[a] * row[b];
                }
                for (c, f) in coefficients[a * kept..(a + 1) * kept]
                    .iter_mut()
                    .zip(features)
                {
                    *c += weight * row[a] * f;
                }
            }
        }
        if inside < RUNS_PER_REGRESSOR * r {
            return false;
        }
        for a in 0..r {
            for b in 0..a {
                gram[b * r + a] = gram[a * r + b];
            }
        }
        if cholesky_in_place(&mut gram, r, PivotRule::Angle(RANK_TOLERANCE)).is_err() {
            return false;
        }
        let mut column = vec![0.0; r];
        for k in 0..kept {
            for a in 0..r {
                column[a] = coefficients[a * kept + k];
            }
            solve_cholesky_in_place(&gram, r, &mut column);
            for a in 0..r {
                coefficients[a * kept + k] = column[a];
            }
        }
        true
    }

    /// The run nearest `point` and its squared distance.
    fn nearest(&self, point: &[f64]) -> (usize, f64) {
        self.points
            .chunks_exact(self.q)
            .map(|x| {
                x.iter()
                    .zip(point)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
            })
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |best, (s, d)| if d < best.1 { (s, d) } else { best },
            )
    }
}

/// `(1 - d^3)^3` for the distance `d` of `x` from `point` over `width`
/// below 1, else 0; 1 for an infinite width.
fn tricube(x: &[f64], point: &[f64], width: f64) -> f64 {
    if !width.is_finite() {
        return 1.0;
    }
    let d = x
        .iter()
        .zip(point)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt()
        / width;
    if d >= 1.0 {
        0.0
    } else {
        (1.0 - d * d * d).powi(3)
    }
}

#[cfg(test)]
mod tests {
    use super::super::curved::{Curved, curved_combinations, draw_by_weights};
    use super::super::local::Gaussian;
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use twostage_kernels::random::standard_normals;
    use twostage_models::Marginal;

    /// The features' noise sds: a feature whose mean bends fast and pins
    /// the parameter to narrow spikes, one that picks among them, and
    /// noise alone.
    const NOISE: [f64; 3] = [0.1, 0.25, 1.0];
    const PRIOR_SD: f64 = 2.0;

    fn mean_of(z: f64, bend: f64) -> [f64; 3] {
        [(bend * z).sin() + 0.3 * z * z, 0.5 * z, 0.0]
    }

    /// `m` runs drawn from N(0, 1) and their noisy features.
    fn runs(m: usize, bend: f64, rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
        let mut at = vec![0.0; m];
        standard_normals(&mut || rng.next_u64(), &mut at);
        let mut features = Vec::with_capacity(3 * m);
        let mut noise = [0.0; 3];
        for &z in &at {
            standard_normals(&mut || rng.next_u64(), &mut noise);
            for ((mean, sd), e) in mean_of(z, bend).iter().zip(NOISE).zip(noise) {
                features.push(mean + sd * e);
            }
        }
        (at, features)
    }

    /// The exact posterior's mass in bins of 0.05 over [-3, 3], by
    /// quadrature (ten points a bin) of the prior N(0, 2^2) times the
    /// features' Gaussian likelihood.
    fn exact_bins(observed: &[f64; 3], bend: f64) -> Vec<f64> {
        let mut bins = vec![0.0; 120];
        for (b, mass) in bins.iter_mut().enumerate() {
            for k in 0..10 {
                let z = -3.0 + 0.05 * b as f64 + 0.005 * (k as f64 + 0.5);
                let mut log = -0.5 * (z / PRIOR_SD).powi(2);
                for ((mean, sd), s) in mean_of(z, bend).iter().zip(NOISE).zip(observed) {
                    log -= 0.5 * ((s - mean) / sd).powi(2);
                }
                *mass += log.exp();
            }
        }
        let total: f64 = bins.iter().sum();
        bins.iter().map(|m| m / total).collect()
    }

    /// Half the summed differences of the draws' shares of the bins and
    /// the exact masses: the total variation distance, binned.
    fn distance(draws: &[f64], exact: &[f64]) -> f64 {
        let mut shares = vec![0.0; exact.len()];
        for &z in draws {
            let b = ((z + 3.0) / 0.05).floor();
            if (0.0..exact.len() as f64).contains(&b) {
                shares[b as usize] += 1.0 / draws.len() as f64;
            }
        }
        0.5 * shares
            .iter()
            .zip(exact)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
    }

    fn setting() -> ([Marginal; 1], Gaussian) {
        let prior = [Marginal::Normal {
            mu: 0.0,
            sigma: PRIOR_SD,
        }];
        let standard = Gaussian::of_draws(&[-1.0, 1.0], 1, 1.0 / 2f64.sqrt()).expect("spread");
        (prior, standard)
    }

    /// A posterior of narrow spikes where the mean bends as `sin(4 z)`
    /// does: the windowed fit's draws lie within 0.12 of the exact
    /// posterior in total variation (binned), one quadratic's (read by the
    /// combinations of a first set of runs, as the rounds read them)
    /// more than 0.4 away.
    #[test]
    fn a_mean_that_bends_fast_is_followed_window_by_window() {
        let bend = 4.0;
        let mut rng = ChaCha8Rng::seed_from_u64(72);
        let observed = [0.2, 0.15, 0.3];
        let exact = exact_bins(&observed, bend);
        let (prior, proposal) = setting();
        let (at, features) = runs(3000, bend, &mut rng);
        let windowed = Windowed::choose(&at, 1, &features, 3, &observed).expect("a window");
        assert!(windowed.width() < 1.0, "width {}", windowed.width());
        let draws = draw_by_weights(&windowed, &prior, &proposal, 40_000, &mut rng).expect("draws");
        let near = distance(&draws, &exact);
        assert!(near < 0.12, "windowed: {near}");
        let summary = curved_combinations(&at, 1, &features, 3).expect("combinations");
        let (at, features) = runs(3000, bend, &mut rng);
        let curved =
            Curved::fit_read_by(Some(&summary), &at, 1, (&features, 3), &observed).expect("a fit");
        let draws = draw_by_weights(&curved, &prior, &proposal, 40_000, &mut rng).expect("draws");
        let far = distance(&draws, &exact);
        assert!(far > 0.4, "one quadratic: {far}");
    }

    /// Where the mean is a quadratic, a window predicts no better than
    /// one quadratic over all runs: none is chosen.
    #[test]
    fn a_quadratic_mean_keeps_one_quadratic() {
        let mut rng = ChaCha8Rng::seed_from_u64(73);
        let (at, features) = runs(3000, 0.0, &mut rng);
        assert!(Windowed::choose(&at, 1, &features, 3, &[0.1, 0.1, 0.0]).is_none());
    }

    /// A window's fit of features exactly quadratic in two parameters is
    /// exact at any point, left-out run or not, wide or narrow.
    #[test]
    fn a_window_reproduces_a_quadratic_exactly() {
        let mut rng = ChaCha8Rng::seed_from_u64(74);
        let mut at = vec![0.0; 2 * 2000];
        standard_normals(&mut || rng.next_u64(), &mut at);
        let mut rows: Vec<[f64; 2]> = at.chunks_exact(2).map(|z| [z[0], z[1]]).collect();
        rows.sort_by(|a, b| a[0].total_cmp(&b[0]));
        let quadratic = |z: &[f64]| [1.0 + z[0] - 2.0 * z[1] * z[0], 0.5 * z[1] * z[1] - z[0]];
        let runs = Runs {
            q: 2,
            firsts: rows.iter().map(|z| z[0]).collect(),
            points: rows.iter().flatten().copied().collect(),
            features: rows.iter().flat_map(|z| quadratic(z)).collect(),
            kept: 2,
            given: (0..rows.len()).collect(),
        };
        let mut mean = [0.0; 2];
        for (width, skip) in [(f64::INFINITY, Some(0)), (0.5, None), (0.3, Some(1000))] {
            assert!(runs.fitted_mean(&[0.3, -0.2], width, skip, &mut mean));
            let want = quadratic(&[0.3, -0.2]);
            for (got, want) in mean.iter().zip(want) {
                assert!(
                    (got - want).abs() < 1e-9,
                    "{width}: {mean:?} against {want}"
                );
            }
        }
        // Too few runs in a narrow window far out: no fit.
        assert!(!runs.fitted_mean(&[4.0, 4.0], 0.3, None, &mut mean));
    }
}
