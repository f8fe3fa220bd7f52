//! The family of inputs a set of records spans: per input signal, the
//! range of each number of its summary
//! ([`twostage_kernels::input_summary::summarize`]: mean, RMS, peak, mean
//! frequency). An estimator keeps its held-out records' family and says
//! which number of which input puts a record outside it.

pub use twostage_kernels::input_summary::{FAMILY_LEAST_WIDTH, FAMILY_MARGIN, SUMMARY_NAMES};
use twostage_kernels::input_summary::{outside_family, summarize};

use twostage_kernels::input_shape::SHAPE_LEN;

use crate::data::IoData;
use crate::input_shape::{ShapeSample, record_shape_numbers};

/// How many numbers summarize one input signal.
const SUMMARY_LEN: usize = SUMMARY_NAMES.len();

/// The range each summary number of each input signal spans over a set of
/// records.
///
/// ```
/// use twostage_models::{InputFamily, IoData};
/// let quiet = IoData::siso(&[0.0, 1.0, 0.0, -1.0], &[0.0; 4])?;
/// let loud = IoData::siso(&[0.0, 2.0, 0.0, -2.0], &[0.0; 4])?;
/// let mut family = InputFamily::new(1, 1.0);
/// family.include(&quiet);
/// family.include(&loud);
/// assert!(family.deviations(&IoData::siso(&[0.0, 1.5, 0.0, -1.5], &[0.0; 4])?, &["u"]).is_empty());
/// let far = family.deviations(&IoData::siso(&[0.0, 9.0, 0.0, -9.0], &[0.0; 4])?, &["u"]);
/// assert!(far[0].to_string().starts_with("input u: RMS 6.36"));
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct InputFamily {
    /// The records' sample time, in seconds (the frequencies' unit).
    sample_time: f64,
    /// Per input signal, per summary number: the smallest and largest
    /// value seen (`[+inf, -inf]` before any record).
    ranges: Vec<[[f64; 2]; SUMMARY_LEN]>,
    /// Records included.
    records: u64,
    /// A sample of the records' input shapes, from which an estimator
    /// makes its [`crate::InputShapes`] (and stores that, not this).
    #[cfg_attr(feature = "serde", serde(skip))]
    shapes: ShapeSample,
}

/// One way a record's input lies outside a family.
#[derive(Debug, Clone, PartialEq)]
pub struct InputDeviation {
    /// The input signal's name.
    pub signal: String,
    /// Which number of its summary ("RMS", "mean frequency", ...).
    pub quantity: &'static str,
    /// The record's value.
    pub value: f64,
    /// The range the family's records spanned (before the margin).
    pub range: [f64; 2],
}

impl std::fmt::Display for InputDeviation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let unit = if self.quantity == "mean frequency" {
            " Hz"
        } else {
            ""
        };
        let [low, high] = self.range;
        let side = if self.value > high { "above" } else { "below" };
        // One value: every record had the same.
        if low >= high {
            let [value, low] = apart([self.value, low]);
            write!(
                f,
                "input {}: {} {value}{unit} where every training record had {low}{unit}",
                self.signal, self.quantity,
            )
        } else {
            let [value, low, high] = apart([self.value, low, high]);
            write!(
                f,
                "input {}: {} {value}{unit} {side} the training records' {low} to {high}{unit}",
                self.signal, self.quantity,
            )
        }
    }
}

/// `numbers` printed with one count of decimals: the fewest from 3 on at
/// which no two of them print alike (at most 15), so that a message says
/// the digits in which a record's value and the family's range differ.
fn apart<const N: usize>(numbers: [f64; N]) -> [String; N] {
    let print = |decimals: usize| numbers.map(|v| format!("{v:.decimals$}"));
    (3..=15)
        .map(print)
        .find(|shown| {
            shown
                .iter()
                .enumerate()
                .all(|(i, a)| shown[i + 1..].iter().all(|b| a != b))
        })
        .unwrap_or_else(|| print(15))
}

/// A value rounded to 4 significant digits, for messages.
fn significant(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(3 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

impl InputFamily {
    /// An empty family of `inputs` signals sampled every `sample_time` s.
    pub fn new(inputs: usize, sample_time: f64) -> Self {
        Self {
            sample_time,
            ranges: vec![[[f64::INFINITY, f64::NEG_INFINITY]; SUMMARY_LEN]; inputs],
            records: 0,
            shapes: ShapeSample::default(),
        }
    }

    /// Widen the family to hold `record`'s inputs (a record of another
    /// input count is left out).
    pub fn include(&mut self, record: &IoData) {
        if record.n_inputs() == self.ranges.len() {
            self.include_summaries(&self.summaries(record));
        }
    }

    /// The summary numbers of `record`'s inputs, input by input (four
    /// each), then their shapes' numbers
    /// ([`crate::record_shape_numbers`]), as
    /// [`InputFamily::include_summaries`] takes them: what a compressed
    /// shard stores beside a record's features.
    pub fn summaries(&self, record: &IoData) -> Vec<f64> {
        let mut numbers: Vec<f64> = (0..record.n_inputs())
            .flat_map(|j| summarize(record.input(j), self.sample_time))
            .collect();
        numbers.extend(record_shape_numbers(record));
        numbers
    }

    /// Widen the family to hold one record given by its summary numbers
    /// ([`InputFamily::summaries`]); numbers of another count are left out.
    pub fn include_summaries(&mut self, summaries: &[f64]) {
        if summaries.len() != self.summary_len() {
            return;
        }
        let (summaries, shape) = summaries.split_at(SUMMARY_LEN * self.ranges.len());
        self.shapes.include(shape);
        for (ranges, summary) in self
            .ranges
            .iter_mut()
            .zip(summaries.chunks_exact(SUMMARY_LEN))
        {
            for (range, &v) in ranges.iter_mut().zip(summary) {
                range[0] = range[0].min(v);
                range[1] = range[1].max(v);
            }
        }
        self.records += 1;
    }

    /// How many summary numbers a record of this family has (its
    /// shape's included).
    pub fn summary_len(&self) -> usize {
        (SUMMARY_LEN + SHAPE_LEN) * self.ranges.len()
    }

    /// The sample of the records' input shapes.
    pub fn shape_sample(&self) -> &ShapeSample {
        &self.shapes
    }

    /// The family without its sample of shapes, and the sample: what an
    /// estimator stores is the family's ranges and the shapes' density.
    pub fn without_shape_sample(mut self) -> (Self, ShapeSample) {
        let shapes = std::mem::take(&mut self.shapes);
        (self, shapes)
    }

    /// The family of both sets of records (of the same signals and
    /// sampling; `other` is left out otherwise).
    pub fn merge(&mut self, other: &InputFamily) {
        if other.ranges.len() != self.ranges.len()
            || other.sample_time.to_bits() != self.sample_time.to_bits()
        {
            return;
        }
        for (mine, theirs) in self.ranges.iter_mut().zip(&other.ranges) {
            for (m, t) in mine.iter_mut().zip(theirs) {
                m[0] = m[0].min(t[0]);
                m[1] = m[1].max(t[1]);
            }
        }
        self.shapes.merge(&other.shapes);
        self.records += other.records;
    }

    /// Records included.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// The sample time the frequencies are in.
    pub fn sample_time(&self) -> f64 {
        self.sample_time
    }

    /// The input signals it describes.
    pub fn n_inputs(&self) -> usize {
        self.ranges.len()
    }

    /// Input `j`'s range of each summary number, in the order of
    /// [`twostage_kernels::input_summary::SUMMARY_NAMES`].
    pub fn ranges(&self, j: usize) -> Option<&[[f64; 2]; 4]> {
        self.ranges.get(j)
    }

    /// Every number of every input of `record` that lies outside the
    /// family's range as [`twostage_kernels::input_summary::outside_family`]
    /// widens it, named with `names` (the inputs' names). Empty for
    /// a record inside the family, for a family of no records, and for a
    /// record of another input count or sample count below 2 (nothing to
    /// judge).
    pub fn deviations(&self, record: &IoData, names: &[impl AsRef<str>]) -> Vec<InputDeviation> {
        let signals: Vec<&[f64]> = (0..record.n_inputs()).map(|j| record.input(j)).collect();
        self.signal_deviations(&signals, names)
    }

    /// [`InputFamily::deviations`] of a record's input signals, one slice
    /// each.
    pub fn signal_deviations(
        &self,
        signals: &[&[f64]],
        names: &[impl AsRef<str>],
    ) -> Vec<InputDeviation> {
        let mut found = Vec::new();
        if self.records == 0 || signals.len() != self.ranges.len() {
            return found;
        }
        for (j, ranges) in self.ranges.iter().enumerate() {
            let summary = summarize(signals[j], self.sample_time);
            let outside = outside_family(summary, *ranges);
            for (k, quantity) in SUMMARY_NAMES
                .iter()
                .enumerate()
                .filter(|(k, _)| outside[*k])
            {
                found.push(InputDeviation {
                    signal: names
                        .get(j)
                        .map_or_else(|| format!("{}", j + 1), |n| n.as_ref().to_string()),
                    quantity,
                    value: summary[k],
                    range: ranges[k],
                });
            }
        }
        found
    }

    /// Whether the stored ranges are well formed for `inputs` signals: a
    /// decoded family is checked before use.
    pub fn is_consistent(&self, inputs: usize) -> bool {
        self.sample_time.is_finite()
            && self.sample_time > 0.0
            && self.ranges.len() == inputs
            && (self.records == 0
                || self
                    .ranges
                    .iter()
                    .flatten()
                    .all(|[l, h]| l.is_finite() && h.is_finite() && l <= h))
    }

    /// One line per input for people: its mean, RMS, peak and mean
    /// frequency ranges.
    pub fn describe(&self, names: &[impl AsRef<str>]) -> Vec<String> {
        self.ranges
            .iter()
            .enumerate()
            .map(|(j, ranges)| {
                let name = names
                    .get(j)
                    .map_or_else(|| format!("{}", j + 1), |n| n.as_ref().to_string());
                let parts: Vec<String> = ranges
                    .iter()
                    .zip(SUMMARY_NAMES)
                    .map(|([l, h], q)| {
                        let unit = if q == "mean frequency" { " Hz" } else { "" };
                        if l >= h {
                            format!("{q} {}{unit}", significant(*l))
                        } else {
                            format!("{q} {} to {}{unit}", significant(*l), significant(*h))
                        }
                    })
                    .collect();
                format!("{name}: {}", parts.join(", "))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(u: &[f64]) -> IoData {
        IoData::siso(u, &vec![0.0; u.len()]).unwrap_or_default()
    }

    #[test]
    fn a_record_is_judged_by_each_number_with_its_margin() {
        let mut family = InputFamily::new(1, 1.0);
        assert!(family.deviations(&record(&[5.0, -5.0]), &["u"]).is_empty());
        // Two records: RMS 1 and 2 about mean 0, alternating (the highest
        // frequency, 0.5 Hz at T = 1 s).
        family.include(&record(&[1.0, -1.0, 1.0, -1.0]));
        family.include(&record(&[2.0, -2.0, 2.0, -2.0]));
        assert_eq!(family.records(), 2);
        // RMS 2.05 lies inside the margin (2 + 0.1); 2.2 does not.
        assert!(
            family
                .deviations(&record(&[2.05, -2.05, 2.05, -2.05]), &["u"])
                .is_empty()
        );
        let out = family.deviations(&record(&[2.2, -2.2, 2.2, -2.2]), &["u"]);
        let quantities: Vec<&str> = out.iter().map(|d| d.quantity).collect();
        assert_eq!(quantities, ["RMS", "peak"]);
        assert_eq!(
            out[0].to_string(),
            "input u: RMS 2.200 above the training records' 1.000 to 2.000"
        );
        // A slow input of the same size: its frequency is below.
        let slow = family.deviations(&record(&[1.5, 1.5, -1.5, -1.5]), &["u"]);
        assert_eq!(slow.len(), 1);
        assert_eq!(slow[0].quantity, "mean frequency");
        assert_eq!(
            slow[0].to_string(),
            "input u: mean frequency 0.196 Hz where every training record had 0.500 Hz"
        );
    }

    /// Numbers that agree in their first decimals are printed to the
    /// digits in which they differ, each of a message with as many.
    #[test]
    fn a_message_prints_the_digits_that_differ() {
        let deviation = |value: f64, range: [f64; 2]| InputDeviation {
            signal: "u".into(),
            quantity: "mean",
            value,
            range,
        };
        assert_eq!(
            deviation(0.006_04, [0.006_123, 0.006_131]).to_string(),
            "input u: mean 0.00604 below the training records' 0.00612 to 0.00613"
        );
        assert_eq!(
            deviation(1.000_000_2, [1.0, 1.0]).to_string(),
            "input u: mean 1.0000002 where every training record had 1.0000000"
        );
        assert_eq!(
            apart([2.5, 2.5]),
            ["2.500000000000000", "2.500000000000000"]
        );
    }

    /// One input every record had: a record read back from text, or
    /// measured within 1% of its size, is of it; another input is not.
    #[test]
    fn one_shared_input_admits_itself_within_a_measurement_s_error() {
        let u = [0.3, 0.1, -0.4, 0.2];
        let mut family = InputFamily::new(1, 0.5);
        family.include(&record(&u));
        family.include(&record(&u));
        assert!(family.deviations(&record(&u), &["steer"]).is_empty());
        let gain = u.map(|v| v * 1.005);
        assert!(family.deviations(&record(&gain), &["steer"]).is_empty());
        let out = family.deviations(&record(&[0.3, 0.1, -0.4, 0.25]), &["steer"]);
        assert!(!out.is_empty());
        assert!(
            out[0]
                .to_string()
                .contains("where every training record had"),
            "{}",
            out[0]
        );
    }

    /// The records of an oscillator driven by a multisine whose lines fall
    /// to 0.65 at the top of the band, measured with a small offset error
    /// and noise: outside a family of equal lines (its mean frequency),
    /// inside one shaped like one of them.
    #[test]
    fn a_family_shaped_like_a_measured_record_holds_its_blocks() {
        use crate::input_design::{Drawn, Grid, Level, Phases, Spectrum};
        use crate::{InputSignal, experiment_rng};
        use rand_distr::{Distribution, Normal};
        let (n, dt) = (4096, 1.0 / 610.0);
        let multisine = |offset: f64| {
            InputSignal::multisine(
                0.0,
                Drawn::fixed(200.0),
                Grid::Odd,
                Phases::Random,
                Level::Rms(Drawn::between(0.020, 0.025).unwrap()),
                offset,
            )
            .unwrap()
        };
        let falling = Spectrum::table(vec![[0.0, 1.0], [120.0, 1.0], [200.0, 0.65]]).unwrap();
        let plant = multisine(0.006_04).with_spectrum(falling).unwrap();
        let noise = Normal::new(0.0, 0.000_2).unwrap();
        let blocks: Vec<Vec<f64>> = (0..10)
            .map(|b| {
                let mut rng = experiment_rng(7, b);
                let mut u = vec![0.0; n];
                plant.fill(dt, &mut rng, &mut u).unwrap();
                u.iter().map(|v| v + noise.sample(&mut rng)).collect()
            })
            .collect();
        let family_of = |design: &InputSignal| {
            let mut family = InputFamily::new(1, dt);
            for e in 0..200 {
                let mut u = vec![0.0; n];
                design.fill(dt, &mut experiment_rng(8, e), &mut u).unwrap();
                family.include(&record(&u));
            }
            family
        };
        let equal = family_of(&multisine(0.006_12));
        let like = Spectrum::like(&blocks[0]).unwrap();
        let shaped = family_of(&multisine(0.006_12).with_spectrum(like).unwrap());
        for (b, u) in blocks.iter().enumerate() {
            let flagged = equal.deviations(&record(u), &["u"]);
            assert!(
                flagged.iter().map(|d| d.quantity).eq(["mean frequency"]),
                "block {b}: {flagged:?}"
            );
            let shaped = shaped.deviations(&record(u), &["u"]);
            assert!(shaped.is_empty(), "block {b}: {shaped:?}");
        }
    }

    #[test]
    fn families_merge_and_refuse_strangers() {
        let (mut a, mut b) = (InputFamily::new(1, 1.0), InputFamily::new(1, 1.0));
        a.include(&record(&[1.0, -1.0]));
        b.include(&record(&[3.0, -3.0]));
        a.merge(&b);
        assert_eq!(a.records(), 2);
        assert_eq!(a.ranges(0).map(|r| r[1]), Some([1.0, 3.0]));
        let other = InputFamily::new(2, 1.0);
        a.merge(&other);
        assert_eq!(a.records(), 2);
        assert!(a.is_consistent(1) && !a.is_consistent(2));
        assert!(InputFamily::new(1, 1.0).is_consistent(1));
    }
}
