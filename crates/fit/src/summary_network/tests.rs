// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use super::*;
use twostage_compress::Workspace;

fn layout() -> Layout {
    Layout {
        layers: vec![
            ConvShape {
                inputs: 2,
                outputs: 3,
                kernel: 4,
                stride: 2,
            },
            ConvShape {
                inputs: 3,
                outputs: 2,
                kernel: 3,
                stride: 1,
            },
        ],
        head: 4,
        targets: 2,
    }
}

fn wavy(n: usize, phase: f64) -> Vec<f64> {
    (0..n)
        .map(|k| (0.37 * k as f64 + phase).sin() + 0.3 * (1.9 * k as f64).cos())
        .collect()
}

/// Back-propagation against central differences of the loss, weight by
/// weight, convolutions and head alike.
#[test]
fn the_gradient_is_the_losss_slope_in_every_weight() {
    let layout = layout();
    let n = layout.n_weights();
    let weights: Vec<f64> = (0..n)
        .map(|i| 0.4 * ((i * 7919 % 23) as f64 / 11.0 - 1.0))
        .collect();
    let length = 21;
    let mut record = wavy(length, 0.3);
    record.extend(wavy(length, 1.7).iter().map(|v| 0.5 * v * v));
    let y = [0.7, -1.2];
    let mut gradient = vec![0.0; n];
    loss_and_gradient(
        &layout,
        &weights,
        record.clone(),
        length,
        &y,
        Some(&mut gradient),
    );
    let h = 1e-6;
    for i in 0..n {
        let (mut up, mut down) = (weights.clone(), weights.clone());
        up[i] += h;
        down[i] -= h;
        let slope = (loss_and_gradient(&layout, &up, record.clone(), length, &y, None)
            - loss_and_gradient(&layout, &down, record.clone(), length, &y, None))
            / (2.0 * h);
        assert!(
            (gradient[i] - slope).abs() <= 1e-7 * (1.0 + slope.abs()),
            "weight {i}: back-propagated {} against {slope}",
            gradient[i]
        );
    }
}

/// A hand-computed convolution: one channel, kernel [1, -1], stride 2 on
/// [0, 1, 3, 6, 10] gives tanh(-1), tanh(-3) (the kernel at 0 and 2), and
/// the summary is their mean and the mean of their squares: the forward
/// pass the training differentiates is the one the compressor runs.
#[test]
fn a_convolution_and_its_average_by_hand() {
    let layers = vec![ConvShape {
        inputs: 1,
        outputs: 1,
        kernel: 2,
        stride: 2,
    }];
    let weights = vec![1.0, -1.0, 0.0];
    let record = vec![0.0, 1.0, 3.0, 6.0, 10.0];
    let (a, b) = ((-1.0f64).tanh(), (-3.0f64).tanh());
    let want = [(a + b) / 2.0, (a * a + b * b) / 2.0];
    let pass = forward_convolutions(&layers, &weights, record.clone(), 5);
    let trained_path = pooled(&pass, 1);
    let network = SummaryNetwork::new(vec![1.0], layers, weights).unwrap();
    let y = Array2::from_shape_vec((5, 1), record).unwrap();
    let none = Array2::<f64>::zeros((5, 0));
    let mut out = [0.0; 2];
    network
        .summarize(none.view(), y.view(), &mut Workspace::new(), &mut out)
        .unwrap();
    for ((got, train), want) in out.iter().zip(&trained_path).zip(want) {
        assert!((got - want).abs() < 1e-15, "{out:?} against {want}");
        assert_eq!(got.to_bits(), train.to_bits());
    }
}

/// Records `y = tanh(g u)` of a random input whose level varies from
/// record to record: the gain `g` is in no linear coefficient of the
/// record, the network learns it (held-out error of the standardized
/// gain under a twentieth of its variance).
fn saturating_records(n: usize) -> (Vec<Array2<f64>>, Array2<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut records = Vec::new();
    let mut gains = Vec::new();
    for _ in 0..n {
        let gain: f64 = rng.random_range(0.5..3.0);
        let level: f64 = rng.random_range(0.3..1.5);
        let mut record = Array2::zeros((64, 2));
        for k in 0..64 {
            let u = level * rng.random_range(-1.0..1.0f64);
            record[[k, 0]] = u;
            record[[k, 1]] = (gain * u).tanh();
        }
        records.push(record);
        gains.push(gain);
    }
    (records, Array2::from_shape_vec((n, 1), gains).unwrap())
}

#[test]
fn it_learns_a_saturations_gain() {
    let (records, gains) = saturating_records(1200);
    let training = SummaryTraining {
        shape: LearnedShape {
            channels: vec![6, 6],
            kernel: 3,
            stride: 2,
        },
        head: 8,
        epochs: 150,
        patience: 20,
        seed: 11,
        ..SummaryTraining::default()
    };
    let trained = training.train(&records, gains.view()).unwrap();
    assert!(
        trained.held_out_mse < 0.05,
        "{} after {} epochs",
        trained.held_out_mse,
        trained.epochs
    );
    assert_eq!(trained.network.n_features(), 12);
}

/// The same seed, the same bits, on one thread as on three.
#[test]
fn the_same_seed_gives_the_same_bits_at_any_thread_count() {
    let (records, gains) = saturating_records(300);
    let training = SummaryTraining {
        epochs: 3,
        seed: 4,
        ..SummaryTraining::default()
    };
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| training.train(&records, gains.view()).unwrap())
    };
    let (one, three) = (on(1), on(3));
    assert_eq!(one, three);
    let other = SummaryTraining {
        seed: 5,
        ..training.clone()
    };
    assert_ne!(
        other.train(&records, gains.view()).unwrap().network,
        one.network
    );
}

#[test]
fn impossible_shapes_and_settings_are_refused_by_name() {
    let (records, gains) = saturating_records(40);
    let error = |t: SummaryTraining, r: &[Array2<f64>], g: ArrayView2<'_, f64>| {
        t.train(r, g).unwrap_err().to_string()
    };
    let base = SummaryTraining::default();
    let e = error(
        SummaryTraining {
            shape: LearnedShape {
                stride: 6,
                ..LearnedShape::default()
            },
            ..base.clone()
        },
        &records,
        gains.view(),
    );
    assert!(e.contains("stride from 1 to the kernel"), "{e}");
    let e = error(
        SummaryTraining {
            shape: LearnedShape {
                channels: vec![8; 5],
                ..LearnedShape::default()
            },
            ..base.clone()
        },
        &records,
        gains.view(),
    );
    assert!(e.contains("need 125 or more"), "{e}");
    let e = error(base.clone(), &records[..39], gains.view());
    assert!(e.contains("39 records and 40 target rows"), "{e}");
    let mut broken = records.clone();
    broken[7][[5, 1]] = f64::NAN;
    let e = error(base.clone(), &broken, gains.view());
    assert!(e.contains("row 7, column 1"), "{e}");
    let mut silent = records.clone();
    silent.iter_mut().for_each(|r| r.column_mut(0).fill(0.0));
    let e = error(base, &silent, gains.view());
    assert!(e.contains("signal 0 zero in every record"), "{e}");
}

/// A time that is up before the first epoch keeps the initial weights and
/// says why; a time far off changes no bit.
#[test]
fn the_training_stops_when_its_time_is_up() {
    let (records, gains) = saturating_records(120);
    let base = SummaryTraining {
        epochs: 2,
        seed: 3,
        ..SummaryTraining::default()
    };
    let now = std::time::Instant::now();
    let late = SummaryTraining {
        stop_by: Some(now),
        ..base.clone()
    };
    let stopped = late.train(&records, gains.view()).unwrap();
    assert_eq!(stopped.epochs, 0);
    assert_eq!(stopped.reason, TerminationReason::EpochsUntilDeadline);
    assert_eq!(stopped.history.len(), 1);
    let free = base.train(&records, gains.view()).unwrap();
    assert_eq!((free.epochs, free.history.len()), (2, 3));
    assert_ne!(free.reason, TerminationReason::EpochsUntilDeadline);
    let distant = SummaryTraining {
        stop_by: Some(now + std::time::Duration::from_secs(3600)),
        ..base
    };
    assert_eq!(distant.train(&records, gains.view()).unwrap(), free);
}
