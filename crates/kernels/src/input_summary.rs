//! What an experiment's input was like, in a few numbers: its level
//! (mean), its size (RMS about the mean and largest deviation) and where
//! its power lies (a mean frequency). An estimator keeps the range its
//! training records' inputs spanned and says when a record's input lies
//! outside it: an input the estimator never saw is an extrapolation even
//! where the features happen to look familiar.
//!
//! The mean frequency is the one of a sinusoid whose first differences
//! have the same power relative to its own: for `u_k = A sin(2 pi f k T +
//! phi)` the mean square of `u_k - u_(k-1)` is `4 sin(pi f T)^2` times the
//! mean square of `u`, so `f = asin(sqrt(D / (4 V))) / (pi T)` with `D` and
//! `V` those two mean squares. For a broadband input it is a power-weighted
//! average over the spectrum (of `sin(pi f T)^2`), so a band moved up or
//! down moves it. One pass over the samples, no transform: the runtime
//! computes the same numbers on a microcontroller.

/// The numbers of an input summary, in the order of [`summarize`]'s array.
pub const SUMMARY_NAMES: [&str; 4] = ["mean", "RMS", "peak", "mean frequency"];

/// Summarize one input signal sampled every `sample_time` seconds:
/// `[mean, RMS about the mean, largest absolute deviation from the mean,
/// mean frequency in Hz]`. An empty signal is all zeros; a constant one
/// has frequency 0.
///
/// ```
/// use twostage_kernels::input_summary::summarize;
/// // A sinusoid of 3 Hz sampled at 100 Hz, over whole periods.
/// let u: Vec<f64> = (0..1000)
///     .map(|k| 2.0 + 0.5 * (2.0 * std::f64::consts::PI * 3.0 * k as f64 * 0.01).sin())
///     .collect();
/// let [mean, rms, peak, frequency] = summarize(&u, 0.01);
/// assert!((mean - 2.0).abs() < 1e-12);
/// assert!((rms - 0.5 / 2f64.sqrt()).abs() < 1e-12);
/// assert!((peak - 0.5).abs() < 1e-12);
/// assert!((frequency - 3.0).abs() < 1e-2);
/// ```
pub fn summarize(u: &[f64], sample_time: f64) -> [f64; 4] {
    let n = u.len();
    if n == 0 {
        return [0.0; 4];
    }
    let mean = u.iter().sum::<f64>() / n as f64;
    let (mut square, mut peak) = (0.0, 0.0f64);
    for v in u {
        let d = v - mean;
        square += d * d;
        peak = peak.max(d.abs());
    }
    let variance = square / n as f64;
    let frequency = if n < 2 || variance <= 0.0 {
        0.0
    } else {
        let differences = u
            .windows(2)
            .map(|w| (w[1] - w[0]) * (w[1] - w[0]))
            .sum::<f64>()
            / (n - 1) as f64;
        let ratio = (differences / (4.0 * variance)).min(1.0);
        libm::asin(crate::sqrt(ratio)) / (core::f64::consts::PI * sample_time)
    };
    [mean, crate::sqrt(variance), peak, frequency]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sinusoid_reads_back_its_frequency_and_level() {
        let dt = 0.002;
        for f in [1.0, 10.0, 60.0, 200.0] {
            // Whole periods of the record: 2 s.
            let u: std::vec::Vec<f64> = (0..1000)
                .map(|k| 3.0 * (2.0 * core::f64::consts::PI * f * k as f64 * dt + 0.3).cos())
                .collect();
            let [mean, rms, peak, frequency] = summarize(&u, dt);
            assert!(mean.abs() < 1e-9, "{f}: mean {mean}");
            assert!((rms - 3.0 / 2f64.sqrt()).abs() < 1e-9, "{f}: rms {rms}");
            // The samples miss the crest by up to half a step.
            assert!(peak <= 3.0 && peak > 2.8, "{f}: peak {peak}");
            // The differences' mean square has one term fewer than the
            // signal's: a relative error of order 1/N in the ratio.
            assert!(
                (frequency - f).abs() < 2e-3 * f.max(10.0),
                "{f}: {frequency}"
            );
        }
    }

    #[test]
    fn white_noise_reads_a_quarter_of_the_sampling_rate() {
        // Independent samples: D = 2 V, so sin(pi f T)^2 = 1/2 and f is a
        // quarter of the sampling rate. A fixed pseudo-random sequence
        // (a linear congruential generator) stands in for white noise.
        let mut state = 12345u64;
        let u: std::vec::Vec<f64> = (0..200_000)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        let [_, _, _, frequency] = summarize(&u, 0.5);
        assert!((frequency - 0.5).abs() < 0.005, "{frequency}");
    }

    #[test]
    fn constant_and_empty_inputs_have_no_frequency() {
        let bits = |v: [f64; 4]| v.map(f64::to_bits);
        assert_eq!(bits(summarize(&[2.0; 10], 1.0)), bits([2.0, 0.0, 0.0, 0.0]));
        assert_eq!(bits(summarize(&[], 1.0)), bits([0.0; 4]));
        assert_eq!(bits(summarize(&[5.0], 1.0)), bits([5.0, 0.0, 0.0, 0.0]));
    }
}
