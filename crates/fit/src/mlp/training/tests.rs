//! The trainers' plans, the sampled curvature and grown ensembles, tested.

use super::*;
use crate::Predictor;

/// Whether every restart of `fitted` ran by Levenberg-Marquardt.
fn all_by_levenberg_marquardt(fitted: &FittedMlp) -> bool {
    fitted
        .reports
        .iter()
        .all(|r| r.reason.trainer() == "Levenberg-Marquardt")
}

#[test]
fn auto_runs_both_trainers_where_levenberg_marquardt_alone_would_not_fit() {
    let limit = MAX_JACOBIAN_ENTRIES;
    // 222 weights, one target: the Jacobian's 222 entries a sample.
    assert_eq!(
        plan(Trainer::Auto, 3000, &[15, 13, 1], limit),
        Plan::LevenbergMarquardt
    );
    // Two hidden layers, 467 weights, 7 targets: 20e6 / (7 * 467) =
    // 6118 rows for LM, Adam on all 6800.
    assert_eq!(
        plan(Trainer::Auto, 6800, &[8, 20, 10, 7], limit),
        Plan::Both { lm_rows: 6118 }
    );
    // One hidden layer of 30 units shared by 7 targets (487 weights):
    // the structured products keep 30 * 9 + 31 + 7 = 308 entries a
    // sample, so LM takes 20e6 / 308 = 64935 rows.
    assert_eq!(
        plan(Trainer::Auto, 6800, &[8, 30, 7], limit),
        Plan::LevenbergMarquardt
    );
    assert_eq!(
        plan(Trainer::Auto, 100_000, &[8, 30, 7], limit),
        Plan::Both { lm_rows: 64935 }
    );
    assert_eq!(plan(Trainer::Auto, 100, &[100, 49, 1], limit), Plan::Adam);
    assert_eq!(
        plan(Trainer::LevenbergMarquardt, 200_000, &[100, 49, 1], limit),
        Plan::LevenbergMarquardt
    );
    assert_eq!(plan(Trainer::ADAM, 10, &[2, 3, 1], limit), Plan::Adam);
}

/// Beyond the Jacobian's limit Levenberg-Marquardt's curvature is the
/// sample's Gram matrix (as a mean over the sample), its gradient every
/// row's: each compared with the products of a problem of those rows
/// alone, computed the plain way.
#[test]
fn sampled_curvature_is_the_sample_s_gram_beside_every_row_s_gradient() {
    use ndarray::Array2;
    use rand::RngExt;
    let sizes = [3, 5, 1];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let x = Array2::from_shape_fn((700, 3), |_| rng.random_range(-2.0..2.0));
    let t = Array2::from_shape_fn((700, 1), |_| rng.random_range(-1.0..1.0));
    let order: Vec<usize> = (0..700).rev().collect();
    let (held_out, train) = order.split_at(100);
    let problem = |train, curvature_rows| Problem {
        sizes: &sizes,
        offsets: vec![0, 3, 8, 9],
        x: &x,
        t: &t,
        train,
        held_out,
        decay: 0.3,
        curvature_rows,
    };
    let sampled = problem(train, Some(220));
    let n = sampled.n_params();
    let params: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let products = |p: &Problem<'_>| {
        let mut least_squares = NetworkLeastSquares::new(p);
        let mut r = Vec::new();
        let (mut jtj, mut jtr) = (vec![0.0; n * n], vec![0.0; n]);
        least_squares.residuals(&params, &mut r).unwrap();
        least_squares
            .gauss_newton(&params, &r, &mut jtj, &mut jtr)
            .unwrap();
        (jtj, jtr)
    };
    let (jtj, jtr) = products(&sampled);
    let (sample_jtj, _) = products(&problem(&train[..220], None));
    let (_, whole_jtr) = products(&problem(train, None));
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
    // The decay's term on the diagonal is scaled by every row, not the
    // sample's: (decay / 600) where the sample's own problem adds
    // (decay / 220).
    let shift = 0.3 / 220.0 - 0.3 / 600.0;
    for i in 0..n {
        for j in 0..=i {
            let expected = sample_jtj[i * n + j] - if i == j { shift } else { 0.0 };
            assert!(close(jtj[i * n + j], expected), "J'J[{i}, {j}]");
        }
        assert!(close(jtr[i], whole_jtr[i]), "J'r[{i}]");
    }
}

/// A fit beyond the Jacobian's limit trains on every row, its
/// curvature from a sample: the same bits on one thread and on three.
#[test]
fn a_fit_with_sampled_curvature_is_the_same_on_any_thread_count() {
    use ndarray::Array2;
    // The first input sweeps its range with the rows, so the first
    // rows alone see a tenth of it.
    let x = Array2::from_shape_fn((900, 2), |(i, j)| match j {
        0 => i as f64 / 450.0 - 1.0,
        _ => ((i * 37) % 97) as f64 / 48.0 - 1.0,
    });
    let y = Array2::from_shape_fn((900, 1), |(i, _)| {
        (x[[i, 0]] * 2.0).sin() + x[[i, 1]] * x[[i, 1]]
    });
    let mlp = MlpParams::new(&[6])
        .unwrap()
        .restarts(2)
        .max_iterations(40)
        .check()
        .unwrap();
    // 19 weights: LM whole on 100 rows, its curvature from 60.
    let limits = Limits {
        jacobian: 1900,
        curvature: 1140,
    };
    let fit = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| mlp.fit_within(x.view(), y.view(), limits, Begin::Anew))
            .unwrap()
    };
    let one = fit(1);
    assert_eq!(one, fit(3));
    let trainers: Vec<&str> = one.reports.iter().map(|r| r.reason.trainer()).collect();
    assert_eq!(
        trainers,
        ["Levenberg-Marquardt", "Levenberg-Marquardt", "Adam", "Adam"]
    );
    // Under the Jacobian's limit LM alone runs, on every row, its
    // curvature from the same sample.
    let alone = mlp
        .fit_within(
            x.view(),
            y.view(),
            Limits {
                jacobian: LIMITS.jacobian,
                ..limits
            },
            Begin::Anew,
        )
        .unwrap();
    assert_eq!(alone.reports.len(), 2);
    assert!(all_by_levenberg_marquardt(&alone));
    assert_eq!(alone.reports[0], one.reports[0], "the same LM restart");
    // A curvature of 60 rows still steers the steps down the whole
    // loss: the function is fitted over its whole range (its variance
    // is about 0.6).
    let p = one.predict(x.view()).unwrap();
    let mse = (&p - &y).mapv(|e| e * e).mean().unwrap();
    assert!(mse < 1e-3, "{mse}");
}

/// Members added while time is left: a member the stop time cuts
/// short is left out, and those that end by themselves are the
/// restarts a larger ensemble would have trained (their bits).
#[test]
fn members_cut_short_are_left_out_of_a_grown_ensemble() {
    use ndarray::Array2;
    let x = Array2::from_shape_fn((500, 2), |(i, j)| {
        ((i * 31 + j * 7) % 89) as f64 / 44.0 - 1.0
    });
    let y = x.map_axis(ndarray::Axis(1), |r| (2.0 * r[0]).sin() * r[1]);
    let y = y.insert_axis(ndarray::Axis(1));
    let adam = Trainer::Adam {
        learning_rate: 1e-2,
        batch_size: 32,
        epochs: 40,
    };
    let net = |restarts: usize| {
        MlpParams::new(&[5])
            .unwrap()
            .ensemble(true)
            .trainer(adam)
            .restarts(restarts)
            .seed(9)
            .check()
            .unwrap()
    };
    let two = net(2).fit(x.view(), y.view()).unwrap();
    let cut = net(2)
        .stopped_by(std::time::Instant::now())
        .fit_more(&two, x.view(), y.view(), 3)
        .unwrap();
    assert_eq!(cut, two, "every added member was cut short");
    let five = net(2).fit_more(&two, x.view(), y.view(), 3).unwrap();
    assert_eq!(five.n_members(), 5);
    let restarts: Vec<usize> = five.reports().iter().map(|r| r.restart).collect();
    assert_eq!(restarts, [0, 1, 2, 3, 4]);
    assert_eq!(five, net(5).fit(x.view(), y.view()).unwrap());
    let single = MlpParams::new(&[5]).unwrap().check().unwrap();
    assert!(single.fit_more(&two, x.view(), y.view(), 1).is_err());
}

/// Beyond the limit both trainers run, each restart says which by its
/// stop reason, and the kept network is the lowest held-out error of
/// all of them; the Levenberg-Marquardt restarts are those a plain LM
/// fit of the smaller share would run.
#[test]
fn both_trainers_compete_on_the_same_held_out_rows() {
    use ndarray::Array2;
    let x = Array2::from_shape_fn((400, 2), |(i, j)| {
        ((i * 37 + j * 11) % 97) as f64 / 48.0 - 1.0
    });
    let y = Array2::from_shape_fn((400, 1), |(i, _)| {
        (x[[i, 0]] * 2.0).sin() + x[[i, 1]] * x[[i, 1]]
    });
    let mlp = MlpParams::new(&[6])
        .unwrap()
        .restarts(2)
        .trainer(Trainer::Auto)
        .check()
        .unwrap();
    // 19 weights: 2000 entries leave LM 105 of the 340 training rows.
    let both = mlp
        .fit_within(
            x.view(),
            y.view(),
            Limits {
                jacobian: 2000,
                ..LIMITS
            },
            Begin::Anew,
        )
        .unwrap();
    assert_eq!(both.reports.len(), 4);
    let trainers: Vec<&str> = both.reports.iter().map(|r| r.reason.trainer()).collect();
    assert_eq!(
        trainers,
        ["Levenberg-Marquardt", "Levenberg-Marquardt", "Adam", "Adam"]
    );
    let lowest = both
        .reports
        .iter()
        .map(|r| r.validation_mse)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(
        both.best_restart().validation_mse.to_bits(),
        lowest.to_bits()
    );
    // Under the limit: LM alone, as before.
    let alone = mlp
        .fit_within(x.view(), y.view(), LIMITS, Begin::Anew)
        .unwrap();
    assert_eq!(alone.reports.len(), 2);
    assert!(all_by_levenberg_marquardt(&alone));
}
