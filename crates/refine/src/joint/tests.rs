//! The joint fit against closed forms: records as outputs of one, a
//! gain with each record's offset, and the starts it spreads.

use super::*;
use twostage_models::Prior;

/// Every output is `theta` plus noise: residuals `y_j - theta` per
/// output, each a run of its own.
struct ConstantOutputs(Prior);

impl ResidualModel for ConstantOutputs {
    type Error = RefineError;
    fn prior(&self) -> &Prior {
        &self.0
    }
    fn n_residuals(&self, record: &IoData) -> usize {
        record.n_samples() * record.n_outputs()
    }
    fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), Self::Error> {
        let n = record.n_samples();
        for j in 0..record.n_outputs() {
            for (r, y) in r[j * n..(j + 1) * n].iter_mut().zip(record.output(j)) {
                *r = y - theta[0];
            }
        }
        Ok(())
    }
}

/// Two one-output records together are one record of two outputs: the
/// same best fit and the same interval, each output (record) with its
/// own noise model.
#[test]
fn two_records_together_are_one_record_of_two_outputs() {
    let n = 300;
    // Two sequences of different spread and colour, deterministic.
    let a: Vec<f64> = (0..n)
        .map(|t| 1.0 + 0.3 * ((t * t % 17) as f64 / 8.0 - 1.0))
        .collect();
    let b: Vec<f64> = (0..n)
        .map(|t| 1.2 + 0.1 * ((t as f64) * 0.37).sin())
        .collect();
    let u = vec![0.0; n];
    let first = IoData::siso(&u, &a).unwrap();
    let second = IoData::siso(&u, &b).unwrap();
    let mut both = IoData::default();
    both.resize(n, 1, 2);
    both.output_mut(0).copy_from_slice(&a);
    both.output_mut(1).copy_from_slice(&b);
    let fit = Refinement::new(ConstantOutputs(Prior::uniform_box(&[0.0], &[3.0]).unwrap()));
    let singles = [
        SingleEstimate {
            record: &first,
            theta: &[1.0],
            half_widths: Some(&[0.1]),
        },
        SingleEstimate {
            record: &second,
            theta: &[1.2],
            half_widths: Some(&[0.1]),
        },
    ];
    let plan = JointPlan {
        search: SearchStarts {
            from_prior: 3,
            seed: 0,
        },
        alpha: 0.1,
    };
    let joint = fit.joint_estimate(&singles, plan).unwrap();
    let mean = (a.iter().sum::<f64>() + b.iter().sum::<f64>()) / (2 * n) as f64;
    assert!(
        (joint.theta[0] - mean).abs() < 1e-9,
        "{} vs {mean}",
        joint.theta[0]
    );
    let alone = fit.uncertainty(&both, &joint.theta).unwrap();
    let together = joint.uncertainty.unwrap();
    // Each record's own best fit is its mean, with its own interval
    // there: their scatter by the moment estimate, computed apart.
    let own: Vec<(f64, f64)> = [&a, &b]
        .into_iter()
        .zip([&first, &second])
        .map(|(y, record)| {
            let m = y.iter().sum::<f64>() / n as f64;
            (m, fit.uncertainty(record, &[m]).unwrap().sd[0].powi(2))
        })
        .collect();
    let (means, variances): (Vec<f64>, Vec<f64>) = own.into_iter().unzip();
    let tau2 = crate::between_record_variance(&means, &variances).unwrap();
    let between = joint.between.unwrap();
    assert!(
        (between.sd[0] - tau2.sqrt()).abs() <= 1e-6 * tau2.sqrt(),
        "{between:?} against tau^2 {tau2}"
    );
    let under_scatter = 1.0
        / variances
            .iter()
            .map(|v| 1.0 / (v + tau2))
            .sum::<f64>()
            .sqrt();
    assert!((between.joint_sd[0] - under_scatter).abs() <= 1e-6 * under_scatter);
    // The means lie 0.2 apart, far beyond their noise: the scatter
    // sets the joint sd, wider than the sandwich of one record of two
    // outputs (which sees the offsets as slow noise).
    assert_eq!(between.mismatch_sets_width(), [true]);
    assert!(
        under_scatter > 1.5 * alone.sd[0],
        "{under_scatter} {alone:?}"
    );
    assert_eq!(together.sd[0].to_bits(), between.joint_sd[0].to_bits());
    assert_eq!(together.noise_order, alone.noise_order);
    // The records' own losses add up to the search's.
    let losses = joint.record_losses.unwrap();
    let direct: f64 = a.iter().map(|y| (y - joint.theta[0]).powi(2)).sum();
    assert!((losses[0] - direct).abs() < 1e-9 * direct);
}

/// A gain times the input plus the record's own offset.
struct GainAndOffset(Prior);

impl ResidualModel for GainAndOffset {
    type Error = RefineError;
    fn prior(&self) -> &Prior {
        &self.0
    }
    fn residuals(&self, theta: &[f64], record: &IoData, r: &mut [f64]) -> Result<(), Self::Error> {
        for ((r, u), y) in r.iter_mut().zip(record.input(0)).zip(record.output(0)) {
            *r = y - theta[0] * u - theta[1];
        }
        Ok(())
    }
}

/// Records of one gain, each with its own offset far from the others'
/// and noise: the joint fit is the least-squares solution of the
/// gain and one offset per record (solved here by its normal
/// equations), and the offsets' differences do not make the records
/// disagree.
#[test]
fn own_offsets_and_a_shared_gain_are_the_least_squares_solution() {
    let offsets = [-2.0, 0.5, 3.0];
    let n = 200;
    let records: Vec<IoData> = offsets
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let u: Vec<f64> = (0..n)
                .map(|t| ((t * (k + 3)) as f64 * 0.37).sin() + 0.1 * k as f64)
                .collect();
            let y: Vec<f64> = u
                .iter()
                .enumerate()
                .map(|(t, u)| 1.5 * u + b + 0.05 * (((t * 7 + k) % 13) as f64 / 6.0 - 1.0))
                .collect();
            IoData::siso(&u, &y).unwrap()
        })
        .collect();
    // Normal equations of [u, one-hot record] for (gain, b_0, b_1, b_2).
    let p = 1 + offsets.len();
    let mut a = vec![0.0; p * p];
    let mut rhs = vec![0.0; p];
    for (k, record) in records.iter().enumerate() {
        for (u, y) in record.input(0).iter().zip(record.output(0)) {
            let mut row = vec![0.0; p];
            row[0] = *u;
            row[1 + k] = 1.0;
            for i in 0..p {
                rhs[i] += row[i] * y;
                for j in 0..p {
                    a[i * p + j] += row[i] * row[j];
                }
            }
        }
    }
    // Gaussian elimination without pivoting: the matrix is positive
    // definite.
    for c in 0..p {
        for r in c + 1..p {
            let f = a[r * p + c] / a[c * p + c];
            for j in c..p {
                a[r * p + j] -= f * a[c * p + j];
            }
            rhs[r] -= f * rhs[c];
        }
    }
    let mut solution = vec![0.0; p];
    for c in (0..p).rev() {
        let known: f64 = (c + 1..p).map(|j| a[c * p + j] * solution[j]).sum();
        solution[c] = (rhs[c] - known) / a[c * p + c];
    }
    let fit = Refinement::new(GainAndOffset(
        Prior::uniform_box(&[0.0, -5.0], &[5.0, 5.0]).unwrap(),
    ));
    let starts: Vec<[f64; 2]> = offsets.iter().map(|b| [1.4, b + 0.1]).collect();
    let singles: Vec<SingleEstimate<'_>> = records
        .iter()
        .zip(&starts)
        .map(|(record, theta)| SingleEstimate {
            record,
            theta,
            half_widths: Some(&[0.05, 0.05]),
        })
        .collect();
    let plan = JointPlan {
        search: SearchStarts {
            from_prior: 2,
            seed: 0,
        },
        alpha: 0.1,
    };
    let joint = fit
        .joint_estimate_with_own(&singles, plan, &[false, true])
        .unwrap();
    assert!((joint.theta[0] - solution[0]).abs() < 1e-7, "{joint:?}");
    assert!(joint.theta[1].is_nan() && joint.pooled.theta[1].is_nan());
    for (k, theta) in joint.records_theta.iter().enumerate() {
        assert_eq!(theta[0].to_bits(), joint.theta[0].to_bits());
        assert!((theta[1] - solution[1 + k]).abs() < 1e-7, "{theta:?}");
    }
    assert!(joint.pooled.disagreeing.is_empty());
    let records = joint.records_uncertainty.unwrap();
    let plant = joint.uncertainty.unwrap();
    assert!(plant.sd[0] > 0.0 && plant.sd[1].is_nan());
    assert_eq!(plant.sd[0].to_bits(), records[2].sd[0].to_bits());
    assert!(records.iter().all(|u| u.sd[1] > 0.0 && u.sd[1] < 0.05));
    // All of them the plant's: one offset forced on every record
    // fits worse than each record's own.
    let forced = fit.joint_estimate(&singles, plan).unwrap();
    let loss = |losses: Option<Vec<f64>>| losses.unwrap().iter().sum::<f64>();
    assert!(loss(forced.record_losses) > 10.0 * loss(joint.record_losses));
    assert_eq!(forced.records_theta[0], forced.theta);
}

/// Without own parameters the pooled interval spreads the first
/// starts even where a record has no interval of its own (one out of
/// the estimator's distribution, say): the pooled point, its two
/// corners, the prior's starts and each record's estimate.
#[test]
fn the_pooled_interval_spreads_the_starts_whatever_a_record_lacks() {
    let u = vec![0.0; 50];
    let a = IoData::siso(&u, &[1.0; 50]).unwrap();
    let b = IoData::siso(&u, &[1.2; 50]).unwrap();
    let fit = Refinement::new(ConstantOutputs(Prior::uniform_box(&[0.0], &[3.0]).unwrap()));
    let singles = [
        SingleEstimate {
            record: &a,
            theta: &[1.0],
            half_widths: Some(&[0.1]),
        },
        SingleEstimate {
            record: &b,
            theta: &[1.2],
            half_widths: None,
        },
    ];
    let plan = JointPlan {
        search: SearchStarts {
            from_prior: 2,
            seed: 0,
        },
        alpha: 0.1,
    };
    let joint = fit.joint_estimate(&singles, plan).unwrap();
    assert_eq!(joint.search.descents, 3 + 2 + 2);
}
