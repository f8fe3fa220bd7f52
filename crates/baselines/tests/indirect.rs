//! Indirect inference against independent computations of its loss.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage_baselines::InvalidSetting;
use twostage_baselines::{
    BaselineError, COMMON_NUMBERS_SEED, IndirectInference, IndirectObjective, RecordEstimator,
    WEIGHTING_SEED, Weighting,
};
use twostage_compress::{Arx, Compressor};
use twostage_models::{Benchmark, IoData, Simulator, experiment_rng};

fn simulate(model: &Benchmark, theta: f64, seed: u64, index: u64) -> IoData {
    let mut record = model.spec().new_record();
    model
        .simulate(&[theta], &mut experiment_rng(seed, index), &mut record)
        .unwrap();
    record
}

/// Features by the QR path (the objective uses the fast path).
fn features(arx: &Arx, record: &IoData) -> Vec<f64> {
    arx.compress(record.inputs(), record.outputs()).unwrap()
}

/// Inverse by Gauss-Jordan elimination with partial pivoting: a second
/// algorithm beside the objective's Cholesky and triangular solve.
fn inverse(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = a.len();
    let mut m: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
            .unwrap();
        m.swap(c, p);
        let d = m[c][c];
        for v in &mut m[c] {
            *v /= d;
        }
        for r in 0..n {
            if r != c {
                let f = m[r][c];
                let pivot = m[c].clone();
                for (v, p) in m[r].iter_mut().zip(pivot) {
                    *v -= f * p;
                }
            }
        }
    }
    m.into_iter().map(|r| r[n..].to_vec()).collect()
}

#[test]
fn the_weighted_loss_is_the_quadratic_form_with_the_inverse_sample_covariance() {
    let model = Benchmark::builder().n_samples(400).build().unwrap();
    let arx = Arx::new(2, 2).unwrap();
    let (seed, s, count) = (7, 4, 60);
    let objective = IndirectObjective::new(
        model.clone(),
        arx,
        s,
        Weighting::InverseCovariance { simulations: count },
        seed,
    )
    .unwrap();
    // The sample covariance of the weighting records, by two passes.
    let weighting: Vec<Vec<f64>> = (0..count)
        .map(|i| {
            features(
                &arx,
                &simulate(&model, 0.0, seed ^ WEIGHTING_SEED, i as u64),
            )
        })
        .collect();
    let n = arx.n_features();
    let mean: Vec<f64> = (0..n)
        .map(|j| weighting.iter().map(|f| f[j]).sum::<f64>() / count as f64)
        .collect();
    let cov: Vec<Vec<f64>> = (0..n)
        .map(|a| {
            (0..n)
                .map(|b| {
                    weighting
                        .iter()
                        .map(|f| (f[a] - mean[a]) * (f[b] - mean[b]))
                        .sum::<f64>()
                        / (count - 1) as f64
                })
                .collect()
        })
        .collect();
    // L L' reproduces it.
    let l = objective.weighting_factor().unwrap();
    for a in 0..n {
        for b in 0..n {
            let llt: f64 = (0..n).map(|k| l[a * n + k] * l[b * n + k]).sum();
            assert!(
                (llt - cov[a][b]).abs() <= 1e-9 * cov[a][a].max(cov[b][b]),
                "C[{a}][{b}]"
            );
        }
    }
    let w = inverse(&cov);
    let data = simulate(&model, -0.45, 99, 0);
    let beta = features(&arx, &data);
    for theta in [-0.5, -0.45, 0.1, 0.8] {
        let bar: Vec<f64> = (0..s)
            .map(|k| {
                features(
                    &arx,
                    &simulate(&model, theta, seed ^ COMMON_NUMBERS_SEED, k as u64),
                )
            })
            .fold(vec![0.0; n], |acc, f| {
                acc.iter().zip(&f).map(|(a, b)| a + b / s as f64).collect()
            });
        let d: Vec<f64> = beta.iter().zip(&bar).map(|(a, b)| a - b).collect();
        let expected: f64 = (0..n)
            .map(|a| (0..n).map(|b| d[a] * w[a][b] * d[b]).sum::<f64>())
            .sum();
        let loss = objective.loss(&[theta], &data).unwrap();
        assert!(
            (loss - expected).abs() <= 1e-7 * expected,
            "theta {theta}: {loss} vs {expected}"
        );
    }
}

#[test]
fn a_record_of_the_common_stream_has_zero_loss_at_its_truth_and_is_found() {
    let model = Benchmark::new();
    let arx = Arx::new(5, 5).unwrap();
    let (seed, truth) = (3, 0.37);
    let data = simulate(&model, truth, seed ^ COMMON_NUMBERS_SEED, 0);
    let objective =
        IndirectObjective::new(model.clone(), arx, 1, Weighting::Identity, seed).unwrap();
    assert!(objective.loss(&[truth], &data).unwrap() < 1e-24);
    assert!(objective.loss(&[truth + 0.01], &data).unwrap() > 1e-8);
    let ii = IndirectInference::new(model, arx, 10)
        .simulations(1)
        .weighting(Weighting::Identity)
        .seed(seed)
        .build()
        .unwrap();
    // The loss oscillates with sin(50 theta^2) like the likelihood: a
    // descent from its basin converges to the truth...
    let descent = ii.descend(&data, vec![truth + 0.02]).unwrap();
    assert!((descent.theta[0] - truth).abs() < 1e-6, "{descent:?}");
    assert!(descent.loss < 1e-12, "{descent:?}");
    // ...and every other descent ends higher.
    let descents = ii.descents(&data).unwrap();
    for d in &descents {
        assert!(d.loss >= descent.loss, "{d:?}");
    }
}

#[test]
fn bad_settings_and_records_are_refused_with_the_reason() {
    let model = Benchmark::builder().n_samples(200).build().unwrap();
    let arx = Arx::new(5, 5).unwrap();
    let setting = |r: Result<_, BaselineError>| match r.map(|_| ()).unwrap_err() {
        BaselineError::InvalidSetting(InvalidSetting { name, value, .. }) => (name, value),
        other => panic!("expected a setting error, got {other}"),
    };
    let e = setting(IndirectInference::new(model.clone(), arx, 0).build());
    assert_eq!(e, ("starts", "0".to_string()));
    let e = setting(
        IndirectInference::new(model.clone(), arx, 1)
            .simulations(0)
            .build(),
    );
    assert_eq!(e, ("simulations per theta", "0".to_string()));
    let e = IndirectInference::new(model.clone(), arx, 1)
        .weighting(Weighting::InverseCovariance { simulations: 10 })
        .build()
        .map(|_| ())
        .unwrap_err();
    assert!(
        matches!(&e, BaselineError::InvalidSetting(InvalidSetting { name: "weighting simulations", value, .. }) if value == "10"),
        "{e}"
    );
    assert!(e.to_string().contains("more than the 10 features"), "{e}");
    let ii = IndirectInference::new(model, arx, 1).build().unwrap();
    let flat = IoData::siso(&[1.0; 200], &[0.5; 200]).unwrap();
    assert!(ii.estimate(&flat).is_err());
}
