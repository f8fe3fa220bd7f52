//! The shapes of a family's inputs: a sample of its records' input shapes
//! ([`twostage_kernels::input_shape::autocorrelations`]) and how far a
//! record's shape lies from them, the judgement that catches an input of
//! the family's level, size and frequency but of another kind (a step or a
//! slalom among bursts) that [`crate::InputFamily`]'s ranges let pass.

use twostage_kernels::input_shape::{NEIGHBOURS, SHAPE_LEN, autocorrelations, nearest_distance};

use crate::data::IoData;

/// How many records' shapes a family's sample keeps: half become the
/// reference shapes an estimator stores, half calibrate its threshold.
pub const SHAPE_SAMPLE: usize = 2048;

/// The share of the family's own records whose shape lies within the
/// threshold: one record in a hundred is flagged where the validation
/// still speaks for it.
pub const SHAPE_LEVEL: f64 = 0.99;

/// The least spread of a standardized coordinate: an autocorrelation the
/// family's records all share to a hundredth is compared in hundredths,
/// not in the rounding of its last digits.
const LEAST_SCALE: f64 = 0.01;

/// The least threshold, in standardized units: a record of the one
/// shape every reference record had, read back from text, is of it.
const LEAST_THRESHOLD: f64 = 1e-6;

/// What a record's input shape at `distance` from a family's, beyond its
/// `threshold`, means, in words.
///
/// ```
/// let said = twostage_models::input_shape_words(3.2, 1.1);
/// assert!(said.starts_with("input shape: its autocorrelations lie at distance 3.200"));
/// ```
pub fn input_shape_words(distance: f64, threshold: f64) -> String {
    format!(
        "input shape: its autocorrelations lie at distance {distance:.3} from the training \
         records' nearest, beyond the {threshold:.3} that {:.0}% of them stay within (an input \
         of another kind: a hold, a longer or broader steer than the family's)",
        100.0 * SHAPE_LEVEL
    )
}

/// The shape numbers of each of `signals`, signal after signal.
pub fn shape_of(signals: &[&[f64]]) -> Vec<f64> {
    let mut out = Vec::with_capacity(SHAPE_LEN * signals.len());
    for signal in signals {
        let mut rho = [0.0; SHAPE_LEN];
        autocorrelations(signal, &mut rho);
        out.extend_from_slice(&rho);
    }
    out
}

/// The shape numbers of `record`'s inputs.
pub fn record_shape_numbers(record: &IoData) -> Vec<f64> {
    let signals: Vec<&[f64]> = (0..record.n_inputs()).map(|j| record.input(j)).collect();
    shape_of(&signals)
}

/// A uniform sample of at most [`SHAPE_SAMPLE`] records' shapes, the same
/// whatever the order the records came in: each shape is kept by a hash
/// of its bits, the smallest hashes win (a bottom-k sketch, Cohen and
/// Kaplan, 2007), so two samples merge into the sample of both records.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShapeSample {
    /// Shapes with their hashes, by hash, then by bits.
    kept: Vec<(u64, Vec<f64>)>,
}

/// SplitMix64's finalizer over a shape's bits: a well-mixed key whose
/// order is a random one, fixed by the shape alone.
fn shape_hash(shape: &[f64]) -> u64 {
    let mut state = 0x5348_4150_4553_0000u64; // "SHAPES"
    for v in shape {
        state ^= v.to_bits();
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        state = z ^ (z >> 31);
    }
    state
}

fn by_hash_then_bits(a: &(u64, Vec<f64>), b: &(u64, Vec<f64>)) -> std::cmp::Ordering {
    a.0.cmp(&b.0).then_with(|| {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        bits(&a.1).cmp(&bits(&b.1))
    })
}

impl ShapeSample {
    /// Keep `shape` if its hash is among the smallest.
    pub fn include(&mut self, shape: &[f64]) {
        if shape.iter().any(|v| !v.is_finite()) {
            return;
        }
        let entry = (shape_hash(shape), shape.to_vec());
        let at = self
            .kept
            .binary_search_by(|e| by_hash_then_bits(e, &entry))
            .unwrap_or_else(|i| i);
        if at < SHAPE_SAMPLE {
            self.kept.insert(at, entry);
            self.kept.truncate(SHAPE_SAMPLE);
        }
    }

    /// The sample of both sets of records.
    pub fn merge(&mut self, other: &ShapeSample) {
        for (_, shape) in &other.kept {
            self.include(shape);
        }
    }

    /// How many shapes are kept.
    pub fn len(&self) -> usize {
        self.kept.len()
    }

    /// Whether no shape is kept.
    pub fn is_empty(&self) -> bool {
        self.kept.is_empty()
    }
}

/// Where a family's input shapes lie: half its sample of shapes,
/// standardized coordinate by coordinate, and the distance
/// ([`NEIGHBOURS`] nearest) that [`SHAPE_LEVEL`] of the other half's
/// shapes lie within from them. A record farther out has an input of a kind the family did not
/// have: the estimator reads it as it never was trained to.
///
/// ```
/// use twostage_models::{InputShapes, ShapeSample, shape_of};
/// // A family of sine bursts between rests, of many lengths and rates.
/// let burst = |cycles: f64, samples: usize| -> Vec<f64> {
///     (0..500)
///         .map(|k| if k < samples { (std::f64::consts::TAU * cycles * k as f64 / samples as f64).sin() } else { 0.0 })
///         .collect()
/// };
/// let mut sample = ShapeSample::default();
/// for i in 0..600 {
///     let u = burst(0.5 + (i % 5) as f64 * 0.5, 100 + i);
///     sample.include(&shape_of(&[&u]));
/// }
/// let shapes = InputShapes::from_sample(&sample, 1).expect("enough records");
/// let inside = burst(1.5, 250);
/// assert!(shapes.distance(&[&inside]) <= shapes.threshold());
/// // A held step is of another kind.
/// let step: Vec<f64> = (0..500).map(|k| if k > 50 { 0.1 } else { 0.0 }).collect();
/// assert!(shapes.distance(&[&step]) > shapes.threshold());
/// ```
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct InputShapes {
    /// Input signals described.
    inputs: usize,
    /// Per coordinate, the sample's mean and spread (at least
    /// [`LEAST_SCALE`]).
    mean: Vec<f64>,
    scale: Vec<f64>,
    /// The sample's shapes, standardized, row-major.
    reference: Vec<f64>,
    /// The distance that [`SHAPE_LEVEL`] of the calibrating half lie
    /// within.
    threshold: f64,
}

/// Fewer shapes than this give no density: the threshold's rank would
/// rest on a handful of records.
const MIN_SHAPES: usize = 200;

impl InputShapes {
    /// The density of `sample`'s shapes of `inputs` signals; `None` below
    /// 100 shapes, for shapes of another length, and where every shape is
    /// the same (one shared input: [`crate::InputFamily`] compares it
    /// sample by sample).
    ///
    /// The standardization is the whole sample's; the reference is its
    /// first half, and the threshold the calibrating half's conformal
    /// rank.
    pub fn from_sample(sample: &ShapeSample, inputs: usize) -> Option<Self> {
        let dim = SHAPE_LEN * inputs;
        let rows: Vec<&[f64]> = sample.kept.iter().map(|(_, s)| s.as_slice()).collect();
        if inputs == 0 || rows.len() < MIN_SHAPES || rows.iter().any(|r| r.len() != dim) {
            return None;
        }
        let n = rows.len() as f64;
        let mean: Vec<f64> = (0..dim)
            .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n)
            .collect();
        let spread: Vec<f64> = (0..dim)
            .map(|j| (rows.iter().map(|r| (r[j] - mean[j]).powi(2)).sum::<f64>() / n).sqrt())
            .collect();
        if spread.iter().all(|s| *s < 1e-9) {
            return None;
        }
        let scale: Vec<f64> = spread.iter().map(|s| s.max(LEAST_SCALE)).collect();
        let standardized =
            |r: &[f64]| -> Vec<f64> { (0..dim).map(|j| (r[j] - mean[j]) / scale[j]).collect() };
        // The sample is in a random order (by hash): its first half is the
        // reference, its second half's distances from it calibrate the
        // threshold, split-conformally (Vovk et al., "Algorithmic Learning
        // in a Random World", 2005): the rank ceil((m + 1) level) of m.
        let (kept, calibration) = rows.split_at(rows.len() / 2);
        let reference: Vec<f64> = kept.iter().flat_map(|r| standardized(r)).collect();
        let mut nearest = [0.0; NEIGHBOURS];
        let mut own: Vec<f64> = calibration
            .iter()
            .map(|r| nearest_distance(&reference, &standardized(r), None, &mut nearest))
            .collect();
        own.sort_by(f64::total_cmp);
        let rank = ((own.len() as f64 + 1.0) * SHAPE_LEVEL).ceil() as usize;
        let threshold = own[rank.clamp(1, own.len()) - 1].max(LEAST_THRESHOLD);
        Some(Self {
            inputs,
            mean,
            scale,
            reference,
            threshold,
        })
    }

    /// The distance of the shape of `signals` (one slice per input) from
    /// the family's: infinite for another input count or a non-finite
    /// sample.
    pub fn distance(&self, signals: &[&[f64]]) -> f64 {
        if signals.len() != self.inputs {
            return f64::INFINITY;
        }
        let point: Vec<f64> = shape_of(signals)
            .iter()
            .zip(self.mean.iter().zip(&self.scale))
            .map(|(v, (m, s))| (v - m) / s)
            .collect();
        if point.iter().any(|v| !v.is_finite()) {
            return f64::INFINITY;
        }
        nearest_distance(&self.reference, &point, None, &mut [0.0; NEIGHBOURS])
    }

    /// The distance [`SHAPE_LEVEL`] of the family's shapes lie within.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// How many reference shapes it keeps.
    pub fn len(&self) -> usize {
        self.reference.len() / self.mean.len().max(1)
    }

    /// Whether it keeps no shape (never, for one that exists).
    pub fn is_empty(&self) -> bool {
        self.reference.is_empty()
    }

    /// The input signals it describes.
    pub fn n_inputs(&self) -> usize {
        self.inputs
    }
}

/// What a file stores; decoding checks every length and value the
/// distance relies on.
#[cfg(feature = "serde")]
#[derive(serde::Deserialize)]
struct InputShapesFields {
    inputs: usize,
    mean: Vec<f64>,
    scale: Vec<f64>,
    reference: Vec<f64>,
    threshold: f64,
}

#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for InputShapes {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let f = InputShapesFields::deserialize(d)?;
        let dim = SHAPE_LEN * f.inputs;
        let ok = f.inputs > 0
            && f.mean.len() == dim
            && f.scale.len() == dim
            && !f.reference.is_empty()
            && f.reference.len() % dim == 0
            && f.mean.iter().chain(&f.reference).all(|v| v.is_finite())
            && f.scale.iter().all(|v| v.is_finite() && *v > 0.0)
            && f.threshold.is_finite()
            && f.threshold > 0.0;
        if !ok {
            return Err(serde::de::Error::custom(format!(
                "input shapes of {} inputs with {} means, {} scales, {} reference values, \
                 threshold {}",
                f.inputs,
                f.mean.len(),
                f.scale.len(),
                f.reference.len(),
                f.threshold
            )));
        }
        Ok(Self {
            inputs: f.inputs,
            mean: f.mean,
            scale: f.scale,
            reference: f.reference,
            threshold: f.threshold,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distinct shapes spread evenly over the unit cube, one per seed.
    fn shape(seed: u64) -> Vec<f64> {
        (0..SHAPE_LEN)
            .map(|j| (shape_hash(&[seed as f64, j as f64]) >> 11) as f64 / (1u64 << 53) as f64)
            .collect()
    }

    /// The sample does not depend on the order or grouping of records.
    #[test]
    fn samples_merge_in_any_order_to_the_same_shapes() {
        let mut whole = ShapeSample::default();
        for i in 0..5000 {
            whole.include(&shape(i));
        }
        assert_eq!(whole.len(), SHAPE_SAMPLE);
        let (mut a, mut b) = (ShapeSample::default(), ShapeSample::default());
        for i in (0..5000).rev() {
            if i % 3 == 0 {
                a.include(&shape(i));
            } else {
                b.include(&shape(i));
            }
        }
        b.merge(&a);
        assert_eq!(b, whole);
    }

    /// The threshold holds its level for fresh shapes of the family: of
    /// shapes drawn like the sample's, 99% lie within (to the spread of
    /// a binomial over 4000).
    #[test]
    fn the_threshold_holds_the_level_of_fresh_shapes() {
        let mut sample = ShapeSample::default();
        for i in 0..5000 {
            sample.include(&shape(i));
        }
        let shapes = InputShapes::from_sample(&sample, 1).unwrap();
        assert_eq!(shapes.len(), SHAPE_SAMPLE / 2);
        let fresh = (10_000..14_000u64)
            .filter(|&i| {
                let s = shape(i);
                let point: Vec<f64> = s
                    .iter()
                    .zip(shapes.mean.iter().zip(&shapes.scale))
                    .map(|(v, (m, c))| (v - m) / c)
                    .collect();
                nearest_distance(&shapes.reference, &point, None, &mut [0.0; NEIGHBOURS])
                    <= shapes.threshold()
            })
            .count();
        let share = fresh as f64 / 4000.0;
        assert!((0.98..=0.996).contains(&share), "{share}");
    }

    #[test]
    fn one_shape_for_all_or_too_few_records_give_no_density() {
        let mut same = ShapeSample::default();
        for _ in 0..300 {
            same.include(&shape(5));
        }
        assert!(InputShapes::from_sample(&same, 1).is_none());
        let mut few = ShapeSample::default();
        for i in 0..150 {
            few.include(&shape(i));
        }
        assert!(InputShapes::from_sample(&few, 1).is_none());
        assert!(InputShapes::from_sample(&few, 2).is_none());
    }
}
