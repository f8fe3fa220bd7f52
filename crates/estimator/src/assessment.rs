//! One estimate with what is known about how far to trust it, and its
//! interval kept inside the prior's box.

use twostage_compress::FlooredSample;
use twostage_models::InputDeviation;

/// One estimate with what is known about how far to trust it.
#[derive(Debug, Clone, PartialEq)]
pub struct Assessment {
    /// The estimate, clipped to the prior box.
    pub theta: Vec<f64>,
    /// Conformal interval half-widths per parameter, when calibrated: the
    /// same for every record.
    pub half_widths: Option<Vec<f64>>,
    /// Adaptive conformal half-widths for this record, when calibrated:
    /// narrow where the estimator is sure, wide where it is not.
    pub adaptive_half_widths: Option<Vec<f64>>,
    /// Mahalanobis distance of the record's features from the training
    /// features, when the estimator has an envelope.
    pub feature_distance: Option<f64>,
    /// The distance that 99.9% of the training features stay within.
    pub distance_threshold: Option<f64>,
    /// Samples outside the domain of their output's transform (a zero
    /// where the estimator takes logarithms): each was taken at the
    /// smallest value the training records had instead. Empty when the
    /// estimator does not transform its outputs or every sample could be.
    pub floored_samples: Vec<FlooredSample>,
    /// Each way the record's input lies outside the family of inputs the
    /// estimator's held-out records spanned (a level, a peak or a mean
    /// frequency they never had). Empty inside the family, and when the
    /// estimator knows no family.
    pub input_deviations: Vec<InputDeviation>,
    /// How far the shape of the record's input lies from the held-out
    /// records' (the distance of its autocorrelations from their nearest
    /// neighbours', [`twostage_models::InputShapes`]), when the estimator
    /// knows their shapes.
    pub input_shape_distance: Option<f64>,
    /// The distance that 99% of the held-out records' shapes stay within.
    pub input_shape_threshold: Option<f64>,
}

impl Assessment {
    /// Whether the record lies outside what training saw, by its features
    /// or by its input: the estimate is then an extrapolation, and the
    /// validation report and the intervals do not speak for it.
    pub fn out_of_distribution(&self) -> bool {
        self.features_outside() || !self.input_deviations.is_empty() || self.input_shape_outside()
    }

    /// Whether the record's input is of a shape the held-out records'
    /// inputs did not have (a step among bursts, a slalom, broadband
    /// steering), though its level, size and frequency may be theirs.
    pub fn input_shape_outside(&self) -> bool {
        matches!((self.input_shape_distance, self.input_shape_threshold), (Some(d), Some(t)) if (d > t || d.is_nan()))
    }

    /// Whether the record's features lie beyond the envelope's threshold.
    pub fn features_outside(&self) -> bool {
        matches!((self.feature_distance, self.distance_threshold), (Some(d), Some(t)) if d > t)
    }

    /// The half-widths the record's intervals use: the adaptive ones where
    /// calibrated, else the conformal ones, else none.
    pub fn interval_half_widths(&self) -> Option<&[f64]> {
        self.adaptive_half_widths
            .as_deref()
            .or(self.half_widths.as_deref())
    }
}

/// The interval `theta +- half_widths` kept inside the prior's box
/// `[lower, upper]`: a parameter cannot leave its prior's support (a
/// positive one never goes below zero), and neither does its interval;
/// what is cut off held no probability, so the coverage stays.
///
/// ```
/// let (lo, hi) = twostage::interval_in_box(&[0.1, 2.0], &[0.3, 0.5], &[0.0, 1.0], &[5.0, 2.2]);
/// assert_eq!((lo, hi), (vec![0.0, 1.5], vec![0.4, 2.2]));
/// // No interval is no interval.
/// let (lo, _) = twostage::interval_in_box(&[0.1], &[f64::NAN], &[0.0], &[1.0]);
/// assert!(lo[0].is_nan());
/// ```
pub fn interval_in_box(
    theta: &[f64],
    half_widths: &[f64],
    lower: &[f64],
    upper: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    // The runtime on a microcontroller keeps its intervals in the box by
    // the same routine.
    let n = theta
        .len()
        .min(half_widths.len())
        .min(lower.len())
        .min(upper.len());
    let (mut low, mut high) = (vec![0.0; n], vec![0.0; n]);
    twostage_kernels::vector::interval_in_box(
        theta,
        half_widths,
        lower,
        upper,
        &mut low,
        &mut high,
    );
    (low, high)
}
