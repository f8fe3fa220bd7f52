//! Output PCA against records built from known orthogonal directions.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use ndarray::Array2;
use twostage_compress::{CompressError, Compressor, OutputPca};

/// Orthonormal directions on n samples: sines of whole periods.
fn direction(i: usize, n: usize) -> Vec<f64> {
    let v: Vec<f64> = (0..n)
        .map(|k| ((i + 1) as f64 * std::f64::consts::TAU * k as f64 / n as f64).sin())
        .collect();
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    v.into_iter().map(|x| x / norm).collect()
}

/// m records: mean + sum_i c_ri v_i with scales 9, 3, 1, and the true
/// centred scores.
fn records(m: usize, n: usize) -> (Vec<Array2<f64>>, Vec<[f64; 3]>) {
    let dirs: Vec<Vec<f64>> = (0..3).map(|i| direction(i, n)).collect();
    // Zero-mean, mutually orthogonal score sequences over the records, so
    // the principal directions are exactly the v_i (no rotation among them).
    let angle = |r: usize, f: f64| f * std::f64::consts::TAU * r as f64 / m as f64;
    let mut scores: Vec<[f64; 3]> = (0..m)
        .map(|r| {
            [
                9.0 * angle(r, 1.0).cos(),
                3.0 * angle(r, 1.0).sin(),
                angle(r, 2.0).cos(),
            ]
        })
        .collect();
    let mean: Vec<f64> = (0..3)
        .map(|i| scores.iter().map(|s| s[i]).sum::<f64>() / m as f64)
        .collect();
    let recs = scores
        .iter()
        .map(|s| {
            Array2::from_shape_fn((n, 1), |(k, _)| {
                0.5 + (0..3).map(|i| s[i] * dirs[i][k]).sum::<f64>()
            })
        })
        .collect();
    for s in &mut scores {
        for i in 0..3 {
            s[i] -= mean[i];
        }
    }
    (recs, scores)
}

fn check_recovery(m: usize, n: usize) {
    let (recs, scores) = records(m, n);
    let views: Vec<_> = recs.iter().map(|r| r.view()).collect();
    let pca = OutputPca::new(3).unwrap().fit(&views).unwrap();
    for (i, v) in pca.directions().enumerate() {
        let dot: f64 = v.iter().zip(direction(i, n)).map(|(a, b)| a * b).sum();
        assert!(
            (dot.abs() - 1.0).abs() < 1e-9,
            "direction {i}: |cos| = {}",
            dot.abs()
        );
    }
    let u = Array2::<f64>::zeros((n, 1));
    for (record, truth) in recs.iter().zip(&scores).take(5) {
        let alpha = pca.compress(u.view(), record.view()).unwrap();
        for (i, v) in pca.directions().enumerate() {
            let sign: f64 = v
                .iter()
                .zip(direction(i, n))
                .map(|(a, b)| a * b)
                .sum::<f64>()
                .signum();
            assert!(
                (alpha[i] - sign * truth[i]).abs() < 1e-8,
                "score {i}: {} vs {}",
                alpha[i],
                truth[i]
            );
        }
    }
}

#[test]
fn directions_and_scores_are_recovered_with_fewer_samples_than_records() {
    check_recovery(80, 40);
}

#[test]
fn directions_and_scores_are_recovered_with_more_samples_than_records() {
    check_recovery(30, 200);
}

#[test]
fn misuse_gets_an_error_naming_the_cause() {
    let (recs, _) = records(30, 50);
    let views: Vec<_> = recs.iter().map(|r| r.view()).collect();
    let u = Array2::<f64>::zeros((50, 1));
    let unfitted = OutputPca::new(2).unwrap();
    assert!(
        unfitted
            .compress(u.view(), recs[0].view())
            .unwrap_err()
            .to_string()
            .contains("fit it")
    );
    assert!(OutputPca::new(0).is_err());
    let e = OutputPca::new(5).unwrap().fit(&views[..4]).unwrap_err();
    assert!(e.to_string().contains("at least 6 records"), "{e}");
    // The records vary in three directions only.
    let e = OutputPca::new(4).unwrap().fit(&views).unwrap_err();
    assert!(matches!(e, CompressError::RankDeficient { .. }), "{e}");
    let pca = OutputPca::new(2).unwrap().fit(&views).unwrap();
    let short = Array2::<f64>::zeros((49, 1));
    let e = pca.compress(short.view(), short.view()).unwrap_err();
    assert!(
        e.to_string().contains("fitted on records of exactly 50"),
        "{e}"
    );
}

/// A direction whose variance is 1e-14 of the leading one's is still
/// recovered to 1e-6: the SVD of the records keeps the condition number,
/// where the Gram matrix's eigenvectors square it (with these directions,
/// not aligned with the samples, numpy's `eigh` of X'X misses the weak one
/// by 1e-2, the SVD by 3e-10).
#[test]
fn a_weak_direction_is_recovered_beside_a_strong_one() {
    let (n, m) = (6, 40);
    let unit = |v: Vec<f64>| -> Vec<f64> {
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.into_iter().map(|x| x / norm).collect()
    };
    let strong = unit(vec![1.0, 2.0, 3.0, -1.0, 0.5, 2.0]);
    let raw = [2.0, -1.0, 0.0, 1.0, 1.0, 0.0];
    let along: f64 = raw.iter().zip(&strong).map(|(a, b)| a * b).sum();
    let weak = unit(
        raw.iter()
            .zip(&strong)
            .map(|(a, b)| a - along * b)
            .collect(),
    );
    let records: Vec<Array2<f64>> = (0..m)
        .map(|i| {
            // Scores of zero mean, +-1 and +-1e-7, uncorrelated.
            let a = if i % 2 == 0 { 1.0 } else { -1.0 };
            let b = if (i / 2) % 2 == 0 { 1e-7 } else { -1e-7 };
            Array2::from_shape_fn((n, 1), |(k, _)| a * strong[k] + b * weak[k])
        })
        .collect();
    let views: Vec<_> = records.iter().map(|r| r.view()).collect();
    let pca = OutputPca::new(2).unwrap().fit(&views).unwrap();
    for (found, truth) in pca.directions().zip([&strong, &weak]) {
        // Directions come with a sign of their own choosing.
        let sign: f64 = found
            .iter()
            .zip(truth)
            .map(|(f, t)| f * t)
            .sum::<f64>()
            .signum();
        for (f, t) in found.iter().zip(truth) {
            assert!((sign * f - t).abs() < 1e-6, "{found:?} vs {truth:?}");
        }
    }
}
