//! What sharpening reads of a long record: its outputs' means and the
//! sample covariances of its signals at a few lags. For a linear system
//! driven by Gaussian noise the likelihood depends on a record through
//! its second moments alone (up to the record's ends), so a likelihood of
//! them comes near the record's own; stage 1's least-squares coefficients
//! are a few functions of some of them and leave out what the output's
//! power tells (the benchmark's exact posterior splits into modes its ARX
//! coefficients cannot place).

use twostage_models::IoData;

/// Lags of the covariances read, from 0.
pub(crate) const MOMENT_LAGS: usize = 5;
/// Records of at least this many samples are read by their moments;
/// shorter ones (a few counts, say) by stage 1's features, as their
/// moments would be far from Gaussian.
pub(crate) const MOMENTS_FROM: usize = 100;

/// The moments of `record`: each output's mean; each output's
/// autocovariances at lags `0..=lags`; for each later output, its
/// covariances with the earlier one at lags `-lags..=lags`; each output's
/// covariances with each input at lags `-lags..=lags` (the input leading
/// for positive lags). The inputs' own moments are left out: the runs
/// share the record's input. Covariances are of the signals less their
/// means, summed over the overlap and divided by the record's length.
pub(crate) fn second_moments(record: &IoData, lags: usize) -> Vec<f64> {
    let centred = |x: &[f64]| -> Vec<f64> {
        let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
        x.iter().map(|v| v - mean).collect()
    };
    let outputs: Vec<Vec<f64>> = (0..record.n_outputs())
        .map(|j| centred(record.output(j)))
        .collect();
    let inputs: Vec<Vec<f64>> = (0..record.n_inputs())
        .map(|j| centred(record.input(j)))
        .collect();
    let mut moments: Vec<f64> = (0..record.n_outputs())
        .map(|j| {
            let y = record.output(j);
            y.iter().sum::<f64>() / y.len().max(1) as f64
        })
        .collect();
    let every_lag = || (-(lags as isize))..=(lags as isize);
    for (j, y) in outputs.iter().enumerate() {
        moments.extend((0..=lags as isize).map(|lag| covariance(y, y, lag)));
        for earlier in &outputs[..j] {
            moments.extend(every_lag().map(|lag| covariance(y, earlier, lag)));
        }
        for u in &inputs {
            moments.extend(every_lag().map(|lag| covariance(y, u, lag)));
        }
    }
    moments
}

/// `sum_t a(t) b(t - lag) / n` over the samples where both exist.
fn covariance(a: &[f64], b: &[f64], lag: isize) -> f64 {
    let n = a.len().min(b.len());
    let shift = lag.unsigned_abs().min(n);
    let sum: f64 = if lag >= 0 {
        a[shift..n]
            .iter()
            .zip(&b[..n - shift])
            .map(|(x, y)| x * y)
            .sum()
    } else {
        a[..n - shift]
            .iter()
            .zip(&b[shift..n])
            .map(|(x, y)| x * y)
            .sum()
    };
    sum / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of two outputs and one input, by hand: y1 = [1, 2, 3],
    /// y2 = [0, 1, 0], u = [1, 0, 0].
    #[test]
    fn moments_of_a_small_record_match_a_hand_computation() {
        let mut record = IoData::zeros(3, 1, 2);
        record.input_mut(0).copy_from_slice(&[1.0, 0.0, 0.0]);
        record.output_mut(0).copy_from_slice(&[1.0, 2.0, 3.0]);
        record.output_mut(1).copy_from_slice(&[0.0, 1.0, 0.0]);
        let got = second_moments(&record, 1);
        // Centred: y1 = [-1, 0, 1], y2 = [-1/3, 2/3, -1/3], u = [2/3, -1/3, -1/3].
        let third = 1.0 / 3.0;
        let want = [
            2.0,   // mean of y1
            third, // mean of y2
            // y1 autocovariances at lags 0, 1: (1 + 0 + 1) / 3, (0 + 0) / 3
            2.0 / 3.0,
            0.0,
            // y1 with u at lags -1, 0, 1:
            // lag -1: y1(t) u(t+1) = (-1)(-1/3) + 0 (-1/3) = 1/3, over 3
            // lag 0: (-1)(2/3) + 0 + (1)(-1/3) = -1, over 3
            // lag 1: y1(t) u(t-1) = 0 (2/3) + 1 (-1/3) = -1/3, over 3
            third / 3.0,
            -third,
            -third / 3.0,
            // y2 autocovariances: (1/9 + 4/9 + 1/9) / 3, (-2/9 - 2/9) / 3
            2.0 / 9.0,
            -4.0 / 27.0,
            // y2 with y1 at lags -1, 0, 1:
            // lag -1: y2(t) y1(t+1) = (-1/3)(0) + (2/3)(1) = 2/3, over 3
            // lag 0: 1/3 + 0 - 1/3 = 0
            // lag 1: y2(t) y1(t-1) = (2/3)(-1) + (-1/3)(0) = -2/3, over 3
            2.0 / 9.0,
            0.0,
            -2.0 / 9.0,
            // y2 with u at lags -1, 0, 1:
            // lag -1: (-1/3)(-1/3) + (2/3)(-1/3) = -1/9, over 3
            // lag 0: -2/9 - 2/9 + 1/9 = -1/3, over 3
            // lag 1: (2/3)(2/3) + (-1/3)(-1/3) = 5/9, over 3
            -1.0 / 27.0,
            -1.0 / 9.0,
            5.0 / 27.0,
        ];
        assert_eq!(got.len(), want.len());
        for (k, (g, w)) in got.iter().zip(want).enumerate() {
            assert!((g - w).abs() < 1e-12, "moment {k}: {g} against {w}");
        }
    }
}
