#![allow(clippy::unwrap_used)]
use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::super::lbfgs::Objective;
use super::super::likelihood::Likelihood;
use super::super::network::BLOCK_SAMPLES;
use super::*;

fn network(hidden: &[usize], seed: u64) -> Mlp {
    MlpParams::new(hidden)
        .unwrap()
        .restarts(2)
        .seed(seed)
        .check()
        .unwrap()
}

/// The loss's gradient by back-propagation against central differences of
/// the loss, every weight, two components over two parameters (so every
/// kind of head entry, logits, means, diagonal and the entry above it,
/// carries a derivative).
#[test]
fn the_likelihood_gradient_matches_finite_differences() {
    let shape = MixtureShape {
        components: 2,
        dim: 2,
    };
    let sizes = [3, 5, shape.outputs()];
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let x = Array2::from_shape_fn((7, 3), |_| rng.random_range(-1.5..1.5));
    let z = Array2::from_shape_fn((7, 2), |_| rng.random_range(-2.0..2.0));
    let train: Vec<usize> = (0..7).collect();
    let likelihood = Likelihood {
        sizes: &sizes,
        offsets: vec![0, 3, 8, 8 + shape.outputs()],
        head: shape,
        x: &x,
        z: &z,
        train: &train,
        held_out: &train,
        decay: 0.3,
    };
    let params: Vec<f64> = (0..super::super::network::parameter_count(&sizes))
        .map(|_| rng.random_range(-0.8..0.8))
        .collect();
    let mut grad = vec![0.0; params.len()];
    likelihood.gradient(&params, &mut grad);
    let h = 1e-6;
    for (w, &g) in grad.iter().enumerate() {
        let mut plus = params.clone();
        let mut minus = params.clone();
        plus[w] += h;
        minus[w] -= h;
        let numeric = (likelihood.loss(&plus) - likelihood.loss(&minus)) / (2.0 * h);
        assert!(
            (g - numeric).abs() < 1e-6 * (1.0 + numeric.abs()),
            "weight {w}: {g} against {numeric}"
        );
    }
}

/// Rows of `theta = (x + 0.3 e1, -0.5 x + 0.2 (0.6 e1 + 0.8 e2))`, `x`
/// uniform on [-1, 1]: a Gaussian given x with sds 0.3, 0.2 and
/// correlation 0.6.
fn correlated(rows: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = Array2::zeros((rows, 1));
    let mut theta = Array2::zeros((rows, 2));
    for i in 0..rows {
        let v: f64 = rng.random_range(-1.0..1.0);
        let (e1, e2): (f64, f64) = (rng.sample(StandardNormal), rng.sample(StandardNormal));
        x[[i, 0]] = v;
        theta[[i, 0]] = v + 0.3 * e1;
        theta[[i, 1]] = -0.5 * v + 0.2 * (0.6 * e1 + 0.8 * e2);
    }
    (x, theta)
}

/// On a Gaussian given x, the held-out negative log-likelihood comes to
/// the conditional entropy in closed form, `log 2π + log(σ1 σ2 √(1−ρ²)) +
/// 1`, and draws at one x have its mean, sds and correlation.
#[test]
fn a_gaussian_given_the_features_is_learned_with_its_correlation() {
    let (x, theta) = correlated(3000, 1);
    let density = MixtureDensity::new(network(&[16], 2), 2)
        .unwrap()
        .fit(x.view(), theta.view(), &[Support::Real, Support::Real])
        .unwrap();
    let (xt, tt) = correlated(4000, 9);
    let nll = density.mean_nll(xt.view(), tt.view()).unwrap();
    let entropy = (2.0 * std::f64::consts::PI).ln() + (0.3f64 * 0.2 * 0.8).ln() + 1.0;
    assert!(
        (nll - entropy).abs() < 0.05,
        "held-out NLL {nll}, entropy {entropy}"
    );
    let n = 20_000;
    let mut draws = vec![0.0; 2 * n];
    density
        .sample(&[0.5], &mut ChaCha8Rng::seed_from_u64(5), &mut draws)
        .unwrap();
    let mean = |j: usize| draws.iter().skip(j).step_by(2).sum::<f64>() / n as f64;
    let (m0, m1) = (mean(0), mean(1));
    let cov = |a: usize, b: usize, ma: f64, mb: f64| {
        draws
            .chunks_exact(2)
            .map(|d| (d[a] - ma) * (d[b] - mb))
            .sum::<f64>()
            / n as f64
    };
    let (s0, s1) = (cov(0, 0, m0, m0).sqrt(), cov(1, 1, m1, m1).sqrt());
    let rho = cov(0, 1, m0, m1) / (s0 * s1);
    assert!(
        (m0 - 0.5).abs() < 0.03 && (m1 + 0.25).abs() < 0.03,
        "{m0} {m1}"
    );
    assert!(
        (s0 / 0.3 - 1.0).abs() < 0.1 && (s1 / 0.2 - 1.0).abs() < 0.1,
        "{s0} {s1}"
    );
    assert!((rho - 0.6).abs() < 0.08, "{rho}");
}

/// `theta = ±x + noise`, the sign a coin: two components find both modes
/// (half the draws on each side) where one cannot, and score better on
/// held-out rows.
#[test]
fn two_modes_take_two_components() {
    let rows = |n: usize, seed: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = Array2::zeros((n, 1));
        let mut theta = Array2::zeros((n, 1));
        for i in 0..n {
            let v: f64 = rng.random_range(0.5..1.0);
            let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let e: f64 = rng.sample(StandardNormal);
            x[[i, 0]] = v;
            theta[[i, 0]] = sign * v + 0.05 * e;
        }
        (x, theta)
    };
    let (x, theta) = rows(2000, 3);
    let (xt, tt) = rows(2000, 4);
    let fit = |k| {
        MixtureDensity::new(network(&[12], 1), k)
            .unwrap()
            .fit(x.view(), theta.view(), &[Support::Real])
            .unwrap()
    };
    let (one, two) = (fit(1), fit(2));
    let (nll_one, nll_two) = (
        one.mean_nll(xt.view(), tt.view()).unwrap(),
        two.mean_nll(xt.view(), tt.view()).unwrap(),
    );
    assert!(nll_two < nll_one - 1.0, "one {nll_one}, two {nll_two}");
    let mut draws = vec![0.0; 4000];
    two.sample(&[0.8], &mut ChaCha8Rng::seed_from_u64(1), &mut draws)
        .unwrap();
    let above = draws.iter().filter(|&&v| v > 0.0).count() as f64 / 4000.0;
    let near = draws
        .iter()
        .filter(|&&v| (v.abs() - 0.8).abs() < 0.2)
        .count() as f64
        / 4000.0;
    assert!((above - 0.5).abs() < 0.1 && near > 0.9, "{above} {near}");
}

/// A chart whose values sit on their interval's bounds (a tenth of the
/// rows on each) trains, gives finite densities at the bounds, and draws
/// nothing outside them; a positive parameter draws nothing at or below
/// zero.
#[test]
fn values_on_the_bounds_give_draws_inside_the_support() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let n = 1500;
    let x: Array2<f64> = Array2::from_shape_fn((n, 1), |_| rng.random_range(0.0..1.0));
    let theta = Array2::from_shape_fn((n, 2), |(i, j)| match (j, i % 10) {
        (0, 0) => 2.0,
        (0, 1) => 5.0,
        (0, _) => 2.0 + 3.0 * x[[i, 0]],
        _ => (x[[i, 0]] - 0.5).exp() * 0.01,
    });
    let supports = [
        Support::Interval {
            low: 2.0,
            high: 5.0,
        },
        Support::Positive,
    ];
    let density = MixtureDensity::new(network(&[8], 0), 3)
        .unwrap()
        .fit(x.view(), theta.view(), &supports)
        .unwrap();
    for (at, t) in [(0.0, 2.0), (1.0, 5.0)] {
        assert!(density.log_density(&[at], &[t, 0.01]).unwrap().is_finite());
    }
    let mut draws = vec![0.0; 2 * 5000];
    for (k, at) in [0.0, 0.5, 1.0].into_iter().enumerate() {
        density
            .sample(&[at], &mut ChaCha8Rng::seed_from_u64(k as u64), &mut draws)
            .unwrap();
        for d in draws.chunks_exact(2) {
            assert!((2.0..=5.0).contains(&d[0]) && d[1] > 0.0, "{d:?}");
        }
    }
}

/// The same seed gives the same density, bit for bit, on one thread and
/// on several (rows beyond one block, so the sums run in parallel).
#[test]
fn the_density_is_the_same_on_any_thread_count() {
    let (x, theta) = correlated(2 * BLOCK_SAMPLES + 37, 6);
    let fit = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                MixtureDensity::new(
                    MlpParams::new(&[6]).unwrap().restarts(3).check().unwrap(),
                    2,
                )
                .and_then(|d| d.iterations(40))
                .unwrap()
                .fit(x.view(), theta.view(), &[Support::Real, Support::Real])
                .unwrap()
            })
    };
    assert_eq!(fit(1), fit(3));
}

/// A value outside its support is named by row and parameter; no
/// component, or a head wider than a layer may be, is refused.
#[test]
fn what_cannot_be_fitted_is_refused_by_name() {
    let x = Array2::from_shape_fn((20, 1), |(i, _)| i as f64);
    let mut theta = Array2::from_shape_fn((20, 1), |(i, _)| 0.1 + i as f64 / 40.0);
    theta[[13, 0]] = -0.2;
    let fit = |k, theta: &Array2<f64>, support| {
        MixtureDensity::new(network(&[4], 0), k)
            .and_then(|d| d.fit(x.view(), theta.view(), &[support]))
            .unwrap_err()
            .to_string()
    };
    let outside = fit(
        1,
        &theta,
        Support::Interval {
            low: 0.0,
            high: 1.0,
        },
    );
    assert!(outside.contains("row 13, parameter 0: -0.2"), "{outside}");
    assert!(fit(1, &theta, Support::Positive).contains("row 13"));
    assert!(fit(0, &theta, Support::Real).contains("components"));
    let wide = Array2::from_shape_fn((20, 8), |(i, j)| (i * j) as f64);
    let too_wide = MixtureDensity::new(network(&[4], 0), 6)
        .unwrap()
        .fit(x.view(), wide.view(), &[Support::Real; 8])
        .unwrap_err()
        .to_string();
    assert!(too_wide.contains("fewer components"), "{too_wide}");
}

/// A density decodes as it was stored; one whose shapes disagree (a
/// weight missing, another head, an empty interval, a kept restart that
/// is not one) is refused, never indexed out of range.
#[test]
fn a_stored_density_is_decoded_whole_or_refused() {
    let (x, theta) = correlated(200, 2);
    let density = MixtureDensity::new(
        MlpParams::new(&[4]).unwrap().restarts(1).check().unwrap(),
        2,
    )
    .and_then(|d| d.iterations(5))
    .unwrap()
    .fit(x.view(), theta.view(), &[Support::Real, Support::Real])
    .unwrap();
    let bytes = postcard::to_allocvec(&density).unwrap();
    assert_eq!(
        postcard::from_bytes::<FittedMixture>(&bytes).unwrap(),
        density
    );
    let damaged: [fn(&mut FittedMixture); 5] = [
        |d| {
            d.params.pop();
        },
        |d| d.shape.components = 3,
        |d| {
            d.supports[0] = Support::Interval {
                low: 1.0,
                high: 1.0,
            }
        },
        |d| d.best = 1,
        |d| d.spread = 0.0,
    ];
    for (k, damage) in damaged.into_iter().enumerate() {
        let mut bad = density.clone();
        damage(&mut bad);
        let bytes = postcard::to_allocvec(&bad).unwrap();
        assert!(
            postcard::from_bytes::<FittedMixture>(&bytes).is_err(),
            "{k}"
        );
        let fields = FittedMixtureFields {
            features: bad.features,
            unbounded: bad.unbounded,
            supports: bad.supports,
            shape: bad.shape,
            sizes: bad.sizes,
            params: bad.params,
            reports: bad.reports,
            best: bad.best,
            spread: bad.spread,
        };
        let refused = FittedMixture::try_from(fields).unwrap_err().to_string();
        assert!(refused.contains("stored"), "{k}: {refused}");
    }
}

/// Fresh rows like the training's leave the spread near 1; rows whose
/// noise is twice as large widen it near 2, and their likelihood rises.
#[test]
fn the_spread_is_calibrated_on_fresh_rows() {
    let (x, theta) = correlated(3000, 1);
    let mut density = MixtureDensity::new(network(&[16], 2), 2)
        .unwrap()
        .fit(x.view(), theta.view(), &[Support::Real, Support::Real])
        .unwrap();
    let (xf, tf) = correlated(4000, 12);
    let same = density.calibrate_spread(xf.view(), tf.view()).unwrap();
    assert!((same - 1.0).abs() < 0.05, "{same}");
    // The same means, the noise doubled.
    let mut wide = tf.clone();
    for (mut row, v) in wide.rows_mut().into_iter().zip(xf.column(0)) {
        row[0] = v + 2.0 * (row[0] - v);
        row[1] = -0.5 * v + 2.0 * (row[1] + 0.5 * v);
    }
    let before = density.mean_nll(xf.view(), wide.view()).unwrap();
    let doubled = density.calibrate_spread(xf.view(), wide.view()).unwrap();
    let after = density.mean_nll(xf.view(), wide.view()).unwrap();
    assert!((doubled / same - 2.0).abs() < 0.15, "{doubled}");
    assert!(after < before - 0.3, "{before} -> {after}");
}

/// A one-component density of one parameter is a normal given x: the
/// region level of a value z sds off its mean is the normal's
/// two-sided probability P(|Z| < |z|), by the draws' count.
#[test]
fn the_region_level_is_the_normal_s_two_sided_probability() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let x = Array2::from_shape_fn((2000, 1), |_| rng.random_range(-1.0..1.0));
    let theta = Array2::from_shape_fn((2000, 1), |(i, _)| {
        x[[i, 0]] + 0.2 * rng.sample::<f64, _>(StandardNormal)
    });
    let density = MixtureDensity::new(network(&[4], 3), 1)
        .unwrap()
        .fit(x.view(), theta.view(), &[Support::Real])
        .unwrap();
    let mut draws = vec![0.0; 40_000];
    density
        .sample(&[0.3], &mut ChaCha8Rng::seed_from_u64(5), &mut draws)
        .unwrap();
    let mean = draws.iter().sum::<f64>() / draws.len() as f64;
    let sd = (draws.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / draws.len() as f64).sqrt();
    // P(|Z| < 0.6745) = 0.5, P(|Z| < 1.6449) = 0.9, P(|Z| < 2.5758) = 0.99.
    for (z, level) in [(0.0, 0.0), (0.6745, 0.5), (-1.6449, 0.9), (2.5758, 0.99)] {
        let got = density
            .region_level(&[0.3], &draws, &[mean + z * sd])
            .unwrap();
        assert!((got - level).abs() < 0.01, "{z}: {got} against {level}");
    }
    assert!(density.region_level(&[0.3], &draws, &[0.1, 0.2]).is_err());
    assert!(density.region_level(&[0.3], &draws, &[f64::NAN]).is_err());
}

/// Choosing among 1, 2 and 3 components on two modes keeps the count of
/// the lowest held-out loss, the one each count fitted alone on the same
/// rows gives; a density told its count tries that one only.
#[test]
fn a_choosing_density_keeps_the_count_of_the_lowest_held_out_loss() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let n = 1500;
    let x = Array2::from_shape_fn((n, 1), |_| rng.random_range(0.5..1.0));
    let theta = Array2::from_shape_fn((n, 1), |(i, _)| {
        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        sign * x[[i, 0]] + 0.05 * rng.sample::<f64, _>(StandardNormal)
    });
    let fit = |density: MixtureDensity| {
        density
            .fit(x.view(), theta.view(), &[Support::Real])
            .unwrap()
    };
    let alone: Vec<f64> = (1..=3)
        .map(|k| {
            fit(MixtureDensity::new(network(&[8], 2), k).unwrap())
                .best_restart()
                .held_out_nll
        })
        .collect();
    let chooser = MixtureDensity::new(network(&[8], 2), 3)
        .unwrap()
        .choosing_components();
    assert_eq!(chooser.candidates(), vec![1, 2, 3]);
    let chosen = fit(chooser);
    let lowest = alone.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(
        chosen.best_restart().held_out_nll.to_bits(),
        lowest.to_bits()
    );
    assert!(chosen.shape().components >= 2, "{alone:?}");
    let told = MixtureDensity::new(network(&[8], 2), 5).unwrap();
    assert_eq!(told.candidates(), vec![5]);
    assert_eq!(told.choosing_components().candidates(), vec![1, 2, 3, 5]);
}

/// A density whose time is up still gives a density of every count tried
/// (each restart takes a step), says it was cut short, and fits worse on
/// held-out rows than one given its time; without a deadline nothing says
/// it was cut.
#[test]
fn a_deadline_ends_the_fit_and_says_so() {
    let (x, theta) = correlated(1500, 4);
    let supports = [Support::Real, Support::Real];
    let density = MixtureDensity::new(network(&[8], 3), 3)
        .unwrap()
        .choosing_components();
    let cut = density
        .clone()
        .stopped_by(std::time::Instant::now())
        .fit(x.view(), theta.view(), &supports)
        .unwrap();
    let whole = density.fit(x.view(), theta.view(), &supports).unwrap();
    assert!(cut.stopped_at_deadline());
    assert!(!whole.stopped_at_deadline());
    assert!(cut.reports().iter().all(|r| r.iterations >= 1));
    assert!([1, 2, 3].contains(&cut.shape().components));
    let (xt, tt) = correlated(2000, 8);
    let (cut_nll, whole_nll) = (
        cut.mean_nll(xt.view(), tt.view()).unwrap(),
        whole.mean_nll(xt.view(), tt.view()).unwrap(),
    );
    assert!(cut_nll > whole_nll + 0.1, "{cut_nll} against {whole_nll}");
}
