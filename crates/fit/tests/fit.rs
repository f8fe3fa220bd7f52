//! Stage-2 regressors against closed forms, finite differences and each other.

// A panic is how a test fails; reference linear algebra reads best with indices.
#![allow(clippy::unwrap_used, clippy::needless_range_loop)]

use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use twostage_fit::InvalidSetting;
use twostage_fit::{
    FitError, MlpParams, Predictor, Regressor, Ridge, Standardizer, TerminationReason, Trainer,
};

fn uniform(rows: usize, cols: usize, seed: u64) -> Array2<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Array2::from_shape_fn((rows, cols), |_| rng.random_range(-1.0..1.0))
}

#[test]
fn ridge_equals_the_regularized_normal_equations() {
    // Independent check: (Z'Z + lambda I) W = Z'T on the standardized data,
    // solved by Gaussian elimination here.
    let x = uniform(80, 4, 2);
    let y = Array2::from_shape_fn((80, 2), |(i, k)| {
        x[[i, 0]] * (k as f64 + 1.0) - 2.0 * x[[i, 3]] + 0.1 * x[[i, 1]] * x[[i, 2]]
    });
    let lambda = 3.0;
    let model = Ridge::new(lambda).unwrap().fit(x.view(), y.view()).unwrap();
    let (fs, ts) = (Standardizer::fit(x.view()), Standardizer::fit(y.view()));
    let (z, t) = (fs.transform(x.view()), ts.transform(y.view()));
    let n = 4;
    for k in 0..2 {
        let mut a = vec![vec![0.0; n + 1]; n];
        for i in 0..n {
            for j in 0..n {
                a[i][j] = (0..80).map(|r| z[[r, i]] * z[[r, j]]).sum::<f64>()
                    + if i == j { lambda } else { 0.0 };
            }
            a[i][n] = (0..80).map(|r| z[[r, i]] * t[[r, k]]).sum();
        }
        for c in 0..n {
            for r in 0..n {
                if r != c {
                    let f = a[r][c] / a[c][c];
                    for j in c..=n {
                        a[r][j] -= f * a[c][j];
                    }
                }
            }
        }
        let w: Vec<f64> = (0..n).map(|i| a[i][n] / a[i][i]).collect();
        // Compare predictions at a few points.
        for r in [0, 17, 55] {
            let zr: f64 = (0..n).map(|j| w[j] * z[[r, j]]).sum();
            let want = ts.mean()[k] + ts.scale()[k] * zr;
            let got = model.predict(x.view()).unwrap()[[r, k]];
            assert!((got - want).abs() < 1e-10, "{got} vs {want}");
        }
    }
}

/// A ridge fit large enough for faer to block its QR gives the same bits
/// on one thread as on three.
#[test]
fn ridge_is_identical_whatever_the_thread_count() {
    let x = uniform(3000, 40, 8);
    let y = Array2::from_shape_fn((3000, 3), |(i, k)| {
        x[[i, k]] - 0.5 * x[[i, 20 + k]] + 0.1 * x[[i, 39]] * x[[i, 1]]
    });
    let fit = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| Ridge::new(1e-6).unwrap().fit(x.view(), y.view()).unwrap())
    };
    let (one, three) = (fit(1), fit(3));
    let bits = |m: &twostage_fit::FittedLinear| -> Vec<u64> {
        m.weights().iter().map(|w| w.to_bits()).collect()
    };
    assert_eq!(bits(&one), bits(&three));
}

#[test]
fn ridge_refuses_collinear_features_without_a_penalty() {
    let mut x = uniform(30, 3, 3);
    for i in 0..30 {
        x[[i, 2]] = 2.0 * x[[i, 0]] - x[[i, 1]];
    }
    let y = uniform(30, 1, 4);
    let err = Ridge::new(0.0)
        .unwrap()
        .fit(x.view(), y.view())
        .unwrap_err();
    assert!(matches!(err, FitError::RankDeficient { .. }), "{err}");
    assert!(Ridge::new(1e-3).unwrap().fit(x.view(), y.view()).is_ok());
    assert!(matches!(
        Ridge::new(-1.0),
        Err(FitError::InvalidSetting(InvalidSetting {
            name: "lambda",
            ..
        }))
    ));
    let mut bad = y.clone();
    bad[[4, 0]] = f64::NAN;
    let err = Ridge::default().fit(x.view(), bad.view()).unwrap_err();
    assert!(matches!(
        err,
        FitError::NonFinite {
            what: "targets",
            row: 4,
            col: 0,
            ..
        }
    ));
}

/// A smooth nonlinear two-output target.
fn nonlinear(x: &Array2<f64>) -> Array2<f64> {
    Array2::from_shape_fn((x.nrows(), 2), |(i, k)| {
        let (a, b) = (x[[i, 0]], x[[i, 1]]);
        if k == 0 {
            (2.0 * a).sin() + b * b
        } else {
            a * b - 0.5 * b
        }
    })
}

#[test]
fn the_network_fits_what_a_linear_map_cannot() {
    let x = uniform(600, 2, 5);
    let y = nonlinear(&x);
    let x_test = uniform(300, 2, 6);
    let y_test = nonlinear(&x_test);
    let rmse =
        |p: &Array2<f64>| ((p - &y_test).mapv(|v| v * v).sum() / (y_test.len() as f64)).sqrt();
    let linear = Ridge::default().fit(x.view(), y.view()).unwrap();
    let net = MlpParams::new(&[12])
        .unwrap()
        .seed(3)
        .check()
        .unwrap()
        .fit(x.view(), y.view())
        .unwrap();
    let (e_lin, e_net) = (
        rmse(&linear.predict(x_test.view()).unwrap()),
        rmse(&net.predict(x_test.view()).unwrap()),
    );
    assert!(e_lin > 0.2, "linear RMSE {e_lin}");
    assert!(e_net < 0.02, "network RMSE {e_net}");
    assert_eq!(net.reports().len(), 4);
    let best = net.best_restart();
    assert!(
        net.reports()
            .iter()
            .all(|r| r.validation_mse >= best.validation_mse)
    );
}

/// Enough rows for several of the parallel loops' blocks (256 samples),
/// so the Jacobian, the Gauss-Newton products and Adam's gradients are
/// divided over the threads: the file must not notice. Two hidden layers
/// take the Jacobian's products, one (of two targets) the structured ones
/// over several tiles.
#[test]
fn training_is_identical_whatever_the_thread_count() {
    let x = uniform(900, 3, 7);
    let y = nonlinear(&x.slice(ndarray::s![.., 0..2]).to_owned());
    for hidden in [&[6, 4][..], &[12]] {
        training_is_identical_whatever_the_thread_count_for(hidden, &x, &y);
    }
}

fn training_is_identical_whatever_the_thread_count_for(
    hidden: &[usize],
    x: &Array2<f64>,
    y: &Array2<f64>,
) {
    let fit = |threads: usize, trainer: Trainer, seed: u64| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            MlpParams::new(hidden)
                .unwrap()
                .restarts(3)
                .max_iterations(25)
                .trainer(trainer)
                .seed(seed)
                .check()
                .unwrap()
                .fit(x.view(), y.view())
                .unwrap()
        })
    };
    // Mini-batches of 600 rows span three blocks.
    let adam = Trainer::Adam {
        learning_rate: 1e-2,
        batch_size: 600,
        epochs: 15,
    };
    let lbfgs = Trainer::Lbfgs { iterations: 30 };
    for trainer in [Trainer::LevenbergMarquardt, adam, lbfgs] {
        let one = fit(1, trainer, 9);
        assert_eq!(one, fit(2, trainer, 9), "{trainer:?}");
        assert_eq!(one, fit(3, trainer, 9), "{trainer:?}");
        assert_ne!(one, fit(2, trainer, 10), "{trainer:?}");
    }
}

#[test]
fn noisy_targets_stop_early_on_the_held_out_set() {
    // Pure noise: the held-out loss stops improving almost at once.
    let x = uniform(300, 4, 11);
    let y = uniform(300, 1, 12);
    let net = MlpParams::new(&[30])
        .unwrap()
        .restarts(1)
        .patience(5)
        .weight_decay(0.0)
        .check()
        .unwrap()
        .fit(x.view(), y.view())
        .unwrap();
    let report = net.best_restart();
    assert_eq!(
        report.reason,
        TerminationReason::EarlyStopping,
        "{report:?}"
    );
    assert!(report.iterations < 300);
}

#[test]
fn invalid_settings_name_themselves() {
    let err = MlpParams::new(&[]).unwrap().check().unwrap_err();
    assert!(err.to_string().contains("hidden layers"), "{err}");
    let setting = |params: MlpParams| match params.check() {
        Err(FitError::InvalidSetting(InvalidSetting { name, value, .. })) => (name, value),
        other => panic!("expected an invalid setting, got {other:?}"),
    };
    assert_eq!(
        setting(MlpParams::new(&[300]).unwrap()),
        ("hidden layer width", "300".into())
    );
    assert_eq!(
        setting(MlpParams::new(&[5]).unwrap().restarts(0)),
        ("restarts", "0".into())
    );
    assert_eq!(
        setting(MlpParams::new(&[5]).unwrap().validation_fraction(0.9)),
        ("validation_fraction", "0.9".into())
    );
    let net = MlpParams::new(&[3]).unwrap().check().unwrap();
    let err = net
        .fit(uniform(2, 1, 1).view(), uniform(2, 1, 2).view())
        .unwrap_err();
    assert!(matches!(err, FitError::TooFewSamples { .. }), "{err}");
    let fitted = net
        .fit(uniform(50, 2, 1).view(), uniform(50, 1, 2).view())
        .unwrap();
    let mut out = [0.0; 2];
    let e = fitted.predict_into(&[0.0, 0.0], &mut out).unwrap_err();
    assert!(
        matches!(e, FitError::ShapeMismatch(_)),
        "one feature, not two: {e}"
    );
}

#[test]
fn an_ensemble_of_one_is_the_network_and_of_three_is_not_the_best_one() {
    let x = uniform(200, 2, 21);
    let y = nonlinear(&x);
    let fit = |restarts: usize, ensemble: bool| {
        MlpParams::new(&[5])
            .unwrap()
            .restarts(restarts)
            .max_iterations(30)
            .seed(4)
            .ensemble(ensemble)
            .check()
            .unwrap()
            .fit(x.view(), y.view())
            .unwrap()
    };
    let (one_mean, one_best) = (fit(1, true), fit(1, false));
    assert_eq!(
        one_mean.predict(x.view()).unwrap(),
        one_best.predict(x.view()).unwrap()
    );
    let (mean, best) = (fit(3, true), fit(3, false));
    assert_eq!((mean.n_members(), best.n_members()), (3, 1));
    let diff = (&mean.predict(x.view()).unwrap() - &best.predict(x.view()).unwrap())
        .mapv(f64::abs)
        .fold(0.0f64, |m, v| m.max(*v));
    assert!(diff > 1e-9 && diff < 0.5, "largest difference {diff}");
}

#[test]
fn lbfgs_fits_a_smooth_function_as_closely_as_levenberg_marquardt() {
    let x = Array2::from_shape_fn((400, 1), |(i, _)| -1.5 + 3.0 * i as f64 / 399.0);
    let t = x.mapv(|v| (2.0 * v).sin());
    let fit = |trainer: Trainer| {
        let net = MlpParams::new(&[16])
            .unwrap()
            .trainer(trainer)
            .restarts(2)
            .max_iterations(500)
            .patience(50)
            .seed(2)
            .check()
            .unwrap()
            .fit(x.view(), t.view())
            .unwrap();
        let p = net.predict(x.view()).unwrap();
        let rmse = ((&p - &t).mapv(|v| v * v).sum() / 400.0).sqrt();
        (rmse, net)
    };
    let (lm, _) = fit(Trainer::LevenbergMarquardt);
    let (lbfgs, net) = fit(Trainer::Lbfgs { iterations: 3000 });
    assert!(
        lbfgs < 0.01 && lbfgs < 3.0 * lm.max(1e-3),
        "L-BFGS {lbfgs}, LM {lm}"
    );
    assert_eq!(net.best_restart().reason.trainer(), "L-BFGS");
    assert!(
        net.training_summary().contains("2 restarts by L-BFGS"),
        "{}",
        net.training_summary()
    );
    let refused = MlpParams::new(&[4])
        .unwrap()
        .trainer(Trainer::Lbfgs { iterations: 0 })
        .check();
    assert!(
        matches!(
            refused,
            Err(FitError::InvalidSetting(InvalidSetting {
                name: "iterations",
                ..
            }))
        ),
        "{refused:?}"
    );
}

#[test]
fn adam_fits_a_smooth_function() {
    let x = Array2::from_shape_fn((400, 1), |(i, _)| -1.5 + 3.0 * i as f64 / 399.0);
    let t = x.mapv(|v| (2.0 * v).sin());
    let net = MlpParams::new(&[16])
        .unwrap()
        .trainer(Trainer::Adam {
            learning_rate: 1e-2,
            batch_size: 32,
            epochs: 400,
        })
        .restarts(1)
        .patience(40)
        .seed(2)
        .check()
        .unwrap()
        .fit(x.view(), t.view())
        .unwrap();
    let p = net.predict(x.view()).unwrap();
    let rmse = ((&p - &t).mapv(|v| v * v).sum() / 400.0).sqrt();
    assert!(rmse < 0.05, "Adam RMSE {rmse}");
    let refused = MlpParams::new(&[4])
        .unwrap()
        .trainer(Trainer::Adam {
            learning_rate: 0.0,
            batch_size: 8,
            epochs: 5,
        })
        .check();
    assert!(
        matches!(
            refused,
            Err(FitError::InvalidSetting(InvalidSetting {
                name: "learning_rate",
                ..
            }))
        ),
        "{refused:?}"
    );
}
