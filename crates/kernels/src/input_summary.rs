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

/// How far beyond a family's own range a summary number may lie and still
/// be of the family, as a share of the range's width: the range of a few
/// hundred records falls short of the family's by a fraction of its
/// width, and a record just past it is no extrapolation.
pub const FAMILY_MARGIN: f64 = 0.1;

/// The least width a summary number's range is judged by, as a share of
/// the number's size (the mean's size at least the family's smallest
/// RMS). Inputs of one design with one setting (a fixed level, a fixed
/// offset, equal lines) give ranges of no width, and a measured record of
/// that design differs from them by its instruments' gain and offset and
/// by its noise; a record read back from text differs in its last digit:
/// a record within [`FAMILY_MARGIN`] of this share is of the family.
pub const FAMILY_LEAST_WIDTH: f64 = 0.1;

/// Which numbers of an input's summary `[mean, RMS, peak, mean frequency]`
/// lie outside the ranges `[low, high]` a family's records spanned, each
/// widened by [`FAMILY_MARGIN`] of the larger of its width and
/// [`FAMILY_LEAST_WIDTH`] of its size: the one judgement of the host and
/// the runtime (a NaN is outside).
///
/// ```
/// use twostage_kernels::input_summary::outside_family;
/// let family = [[0.0, 1.0], [2.0, 2.0], [5.0, 6.0], [10.0, 10.0]];
/// // Within a tenth of each width; the RMS and frequency within 1% of their size.
/// assert_eq!(outside_family([1.05, 2.01, 6.05, 9.95], family), [false; 4]);
/// assert_eq!(outside_family([1.2, 2.1, 6.2, 10.2], family), [true; 4]);
/// // A mean of no width near zero is judged against the smallest RMS: 1% of 2.
/// let fixed_offset = [[0.5, 0.5], [2.0, 3.0], [5.0, 6.0], [10.0, 11.0]];
/// assert!(!outside_family([0.515, 2.5, 5.5, 10.5], fixed_offset)[0]);
/// assert!(outside_family([0.53, 2.5, 5.5, 10.5], fixed_offset)[0]);
/// assert!(outside_family([f64::NAN, 2.5, 5.5, 10.5], fixed_offset)[0]);
/// ```
pub fn outside_family(summary: [f64; 4], ranges: [[f64; 2]; 4]) -> [bool; 4] {
    let smallest_rms = ranges[1][0].abs();
    core::array::from_fn(|k| {
        let [low, high] = ranges[k];
        let size = low.abs().max(high.abs());
        let size = if k == 0 { size.max(smallest_rms) } else { size };
        let slack = FAMILY_MARGIN * (high - low).max(FAMILY_LEAST_WIDTH * size);
        !(summary[k] >= low - slack && summary[k] <= high + slack)
    })
}

/// Summarize one input signal sampled every `sample_time` seconds:
/// `[mean, RMS about the mean, largest absolute deviation from the mean,
/// mean frequency in Hz]`. An empty signal is all zeros; a constant one
/// has frequency 0. The same numbers as an [`InputAccumulator`] fed the
/// samples one by one (it is what this does).
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
    let mut accumulator = InputAccumulator::new();
    for &v in u {
        accumulator.push(v);
    }
    accumulator.summary(sample_time)
}

/// The `f64` words of [`InputAccumulator::to_words`].
pub const ACCUMULATOR_WORDS: usize = 7;

/// The summary of a signal whose samples arrive one at a time, in seven
/// numbers and no allocation (a stream on a microcontroller keeps one per
/// input): the mean and the sum of squared deviations by Welford's
/// update, which stays accurate for a small variation about a large
/// level, the extremes, and the sum of squared first differences.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputAccumulator {
    /// Samples so far, as a float: exact to 2^53, and the runtime keeps
    /// it among its words without an integer conversion.
    count: f64,
    mean: f64,
    squares: f64,
    low: f64,
    high: f64,
    last: f64,
    differences: f64,
}

impl Default for InputAccumulator {
    fn default() -> Self {
        Self::new()
    }
}

impl InputAccumulator {
    /// No samples yet.
    pub const fn new() -> Self {
        Self {
            count: 0.0,
            mean: 0.0,
            squares: 0.0,
            low: f64::INFINITY,
            high: f64::NEG_INFINITY,
            last: 0.0,
            differences: 0.0,
        }
    }

    /// One more sample.
    pub fn push(&mut self, v: f64) {
        if self.count > 0.0 {
            let d = v - self.last;
            self.differences += d * d;
        }
        self.count += 1.0;
        let delta = v - self.mean;
        self.mean += delta / self.count;
        self.squares += delta * (v - self.mean);
        self.low = self.low.min(v);
        self.high = self.high.max(v);
        self.last = v;
    }

    /// Its state as seven numbers (the count first), for a stream that
    /// keeps its state in a caller's workspace of `f64`.
    pub fn to_words(&self) -> [f64; ACCUMULATOR_WORDS] {
        [
            self.count,
            self.mean,
            self.squares,
            self.low,
            self.high,
            self.last,
            self.differences,
        ]
    }

    /// The accumulator [`InputAccumulator::to_words`] wrote.
    pub fn from_words(words: [f64; ACCUMULATOR_WORDS]) -> Self {
        let [count, mean, squares, low, high, last, differences] = words;
        Self {
            count,
            mean,
            squares,
            low,
            high,
            last,
            differences,
        }
    }

    /// `[mean, RMS, peak, mean frequency]` of the samples so far, as
    /// [`summarize`] says.
    pub fn summary(&self, sample_time: f64) -> [f64; 4] {
        if self.count < 1.0 {
            return [0.0; 4];
        }
        let n = self.count;
        let variance = (self.squares / n).max(0.0);
        let peak = (self.high - self.mean).max(self.mean - self.low).max(0.0);
        let frequency = if self.count < 2.0 || variance <= 0.0 {
            0.0
        } else {
            let ratio = (self.differences / (n - 1.0) / (4.0 * variance)).min(1.0);
            libm::asin(crate::sqrt(ratio)) / (core::f64::consts::PI * sample_time)
        };
        [self.mean, crate::sqrt(variance), peak, frequency]
    }
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
    fn the_running_summary_is_the_two_pass_one() {
        // A small variation about a large level: the two-pass formulas,
        // computed here directly, against the running ones.
        let u: std::vec::Vec<f64> = (0..5000)
            .map(|k| {
                1.0e3 + 1.0e-3 * libm::sin(0.37 * k as f64) + 1.0e-4 * libm::cos(2.1 * k as f64)
            })
            .collect();
        let n = u.len() as f64;
        let mean = u.iter().sum::<f64>() / n;
        let variance = u.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        let peak = u.iter().fold(0.0f64, |m, v| m.max((v - mean).abs()));
        let differences = u
            .windows(2)
            .map(|w| (w[1] - w[0]) * (w[1] - w[0]))
            .sum::<f64>()
            / (n - 1.0);
        let frequency =
            libm::asin(libm::sqrt(differences / (4.0 * variance))) / core::f64::consts::PI;
        let [m, rms, p, f] = summarize(&u, 1.0);
        assert!((m - mean).abs() < 1e-12 * mean, "{m} {mean}");
        assert!((rms / libm::sqrt(variance) - 1.0).abs() < 1e-6, "{rms}");
        assert!((p / peak - 1.0).abs() < 1e-6, "{p} {peak}");
        assert!((f / frequency - 1.0).abs() < 1e-6, "{f} {frequency}");
    }

    #[test]
    fn an_accumulator_kept_as_words_goes_on_to_the_same_bits() {
        let u: std::vec::Vec<f64> = (0..300).map(|k| libm::sin(0.1 * k as f64) + 4.0).collect();
        let mut whole = InputAccumulator::new();
        let mut words = InputAccumulator::new().to_words();
        for &v in &u {
            whole.push(v);
            let mut again = InputAccumulator::from_words(words);
            again.push(v);
            words = again.to_words();
        }
        assert_eq!(InputAccumulator::from_words(words), whole);
        assert_eq!(
            summarize(&u, 0.1).map(f64::to_bits),
            InputAccumulator::from_words(words)
                .summary(0.1)
                .map(f64::to_bits)
        );
    }

    #[test]
    fn the_family_range_is_widened_by_its_margin_on_both_sides() {
        // The margin's edge, computed independently: a tenth of the width
        // (the RMS's range, the mean's scale, is 1 to 3: 0.1 of it is less).
        let family = |range: [f64; 2]| [range, [1.0, 3.0], [5.0, 9.0], [10.0, 20.0]];
        let mean =
            |value: f64, range: [f64; 2]| outside_family([value, 2.0, 7.0, 15.0], family(range))[0];
        let range = [2.0, 6.0];
        assert!(!mean(6.0 + 0.39, range));
        assert!(mean(6.0 + 0.41, range));
        assert!(!mean(2.0 - 0.39, range));
        assert!(mean(2.0 - 0.41, range));
        // A mean of no width: 1% of the smallest RMS, 1, or of itself.
        assert!(!mean(0.5 + 0.0099, [0.5, 0.5]) && mean(0.5 + 0.0101, [0.5, 0.5]));
        assert!(!mean(4.0 + 0.0399, [4.0, 4.0]) && mean(4.0 + 0.0401, [4.0, 4.0]));
        // An RMS, a peak or a frequency of no width: 1% of its size.
        let one = |k: usize, value: f64| {
            let mut summary = [0.0, 2.0, 7.0, 15.0];
            let mut ranges = family([-1.0, 1.0]);
            summary[k] = value;
            ranges[k] = [4.0, 4.0];
            outside_family(summary, ranges)[k]
        };
        for k in 1..4 {
            assert!(!one(k, 4.0399) && !one(k, 3.9601), "number {k}");
            assert!(one(k, 4.0401) && one(k, 3.9599), "number {k}");
        }
        // A range of no width at zero admits zero only.
        let zero = [[0.0, 0.0]; 4];
        assert_eq!(outside_family([0.0; 4], zero), [false; 4]);
        assert!(outside_family([1e-300, 0.0, 0.0, 0.0], zero)[0]);
    }

    #[test]
    fn constant_and_empty_inputs_have_no_frequency() {
        let bits = |v: [f64; 4]| v.map(f64::to_bits);
        assert_eq!(bits(summarize(&[2.0; 10], 1.0)), bits([2.0, 0.0, 0.0, 0.0]));
        assert_eq!(bits(summarize(&[], 1.0)), bits([0.0; 4]));
        assert_eq!(bits(summarize(&[5.0], 1.0)), bits([5.0, 0.0, 0.0, 0.0]));
    }
}
