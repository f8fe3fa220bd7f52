//! Pointwise transforms of the output signals before stage 1: what a
//! careful human does to populations or concentrations that span decades
//! (take logarithms, so that multiplicative noise becomes additive and a
//! tenfold change weighs the same at every level) before fitting a linear
//! structure to them.
//!
//! A transform is part of the compressor, hence of the estimator: an
//! estimate applies it to the measured record by itself. On the training
//! records a sample outside the transform's domain is an error (the
//! record fails like any record that cannot be compressed); on the
//! estimate path ([`Compressor::compress_fast_into`]) it is replaced by the
//! smallest value of the domain the training records showed, and listed
//! in the workspace ([`Workspace::floored_samples`]) so that the estimate
//! can say which samples it could not take as they were.

use crate::InvalidSetting;
use std::fmt;

use ndarray::{ArrayView2, Axis};
use serde::{Deserialize, Serialize};

use super::CompressorConfig;
use crate::error::{CompressError, Result};
use crate::signals::name;
use crate::workspace::FlooredSample;
use crate::{Compressor, Workspace};

/// A map of one output signal, sample by sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SignalTransform {
    /// The signal as it is (`id`).
    Identity,
    /// The natural logarithm (`log`), for signals that are always positive.
    Log,
    /// `ln(1 + y)` (`log1p`), for counts and other signals that reach zero.
    Log1p,
}

impl SignalTransform {
    /// Every transform, in the order the specifications list them.
    pub const ALL: [Self; 3] = [Self::Identity, Self::Log, Self::Log1p];

    /// The name the specifications use (`id`, `log`, `log1p`).
    pub fn spec(self) -> &'static str {
        match self {
            Self::Identity => "id",
            Self::Log => "log",
            Self::Log1p => "log1p",
        }
    }

    /// Whether `value` lies in the transform's domain (finite values only).
    pub fn accepts(self, value: f64) -> bool {
        value.is_finite()
            && match self {
                Self::Identity => true,
                Self::Log => value > 0.0,
                Self::Log1p => value > -1.0,
            }
    }

    /// The transformed value (`value` in the domain).
    ///
    /// ```
    /// use twostage_compress::SignalTransform;
    /// assert_eq!(SignalTransform::Log.apply(std::f64::consts::E), 1.0);
    /// assert_eq!(SignalTransform::Log1p.apply(0.0), 0.0);
    /// assert_eq!(SignalTransform::Identity.apply(-3.5), -3.5);
    /// ```
    pub fn apply(self, value: f64) -> f64 {
        match self {
            Self::Identity => value,
            Self::Log => value.ln(),
            Self::Log1p => value.ln_1p(),
        }
    }

    /// What the domain is, for messages.
    fn domain(self) -> &'static str {
        match self {
            Self::Identity => "every finite value",
            Self::Log => "positive values only",
            Self::Log1p => "values above -1 only",
        }
    }
}

impl std::str::FromStr for SignalTransform {
    type Err = CompressError;

    fn from_str(text: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|t| t.spec() == text.trim())
            .ok_or_else(|| {
                CompressError::InvalidSetting(InvalidSetting {
                    name: "output transform",
                    value: text.to_string(),
                    reason: "use id, log or log1p".into(),
                })
            })
    }
}

/// Records a transform's floors are taken from (the smallest value of its
/// domain among them, per output).
pub const TRANSFORM_RECORDS: usize = 1000;

/// Output transforms, then a compressor of the transformed record.
///
/// ```
/// use ndarray::array;
/// use twostage_compress::{Compressor, CompressorConfig};
/// // The logarithm of a single-output record, then its raw samples.
/// let c: CompressorConfig = "log+raw".parse()?;
/// let c = c.for_shape(0, 1, 3)?;
/// let y = array![[1.0], [std::f64::consts::E], [1.0]];
/// let no_input = ndarray::Array2::<f64>::zeros((3, 0));
/// let c = c.prepared([(no_input.view(), y.view())])?;
/// let alpha = c.compress(no_input.view(), y.view())?;
/// assert!((alpha[1] - 1.0).abs() < 1e-15 && alpha[0] == 0.0);
/// assert_eq!(c.spec().as_deref(), Some("log+raw"));
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transformed {
    /// One per output (a single one stands for every output until the
    /// compressor is shaped for its model).
    outputs: Vec<SignalTransform>,
    /// Per output, the smallest value of the domain the training records
    /// showed: what an estimate puts in place of a sample outside the
    /// domain. Empty until prepared.
    floors: Vec<f64>,
    inner: Box<CompressorConfig>,
}

impl Transformed {
    /// `outputs` (one per output signal, or one for all), then `inner`.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for no transform, or an inner
    /// compressor that is itself transformed.
    pub fn new(outputs: Vec<SignalTransform>, inner: CompressorConfig) -> Result<Self> {
        if outputs.is_empty() || matches!(inner, CompressorConfig::Transformed(_)) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "output transform",
                value: format!("{outputs:?} then {inner}"),
                reason: "one transform per output (or one for all), then one compressor that is \
                         not itself transformed"
                    .into(),
            }));
        }
        Ok(Self {
            outputs,
            floors: Vec::new(),
            inner: Box::new(inner),
        })
    }

    /// The transform of each output.
    pub fn transforms(&self) -> &[SignalTransform] {
        &self.outputs
    }

    /// The compressor of the transformed record.
    pub fn inner(&self) -> &CompressorConfig {
        &self.inner
    }

    /// Per output, the smallest value of its transform's domain the
    /// training records showed: what an estimate takes in place of a
    /// sample outside the domain (empty until prepared).
    pub fn floors(&self) -> &[f64] {
        &self.floors
    }

    /// Whether the floors of the estimate path are set.
    pub fn is_prepared(&self) -> bool {
        self.floors.len() == self.outputs.len()
    }

    /// The same transforms for `n_outputs` outputs, with `inner` in place
    /// of the compressor.
    pub(crate) fn shaped(&self, n_outputs: usize, inner: CompressorConfig) -> Result<Self> {
        let outputs = match self.outputs.as_slice() {
            [one] => vec![*one; n_outputs],
            list if list.len() == n_outputs => list.to_vec(),
            list => {
                return Err(CompressError::InvalidSetting(InvalidSetting {
                    name: "output transform",
                    value: self.spec_prefix(),
                    reason: format!(
                        "{} transforms for {n_outputs} output(s): give one per output, or one for \
                         all",
                        list.len()
                    ),
                }));
            }
        };
        let floors = if self.floors.len() == outputs.len() {
            self.floors.clone()
        } else {
            Vec::new()
        };
        Ok(Self {
            outputs,
            floors,
            inner: Box::new(inner),
        })
    }

    /// The transforms as the specification writes them: `log` when one
    /// serves every output, else `log,id,...`.
    fn spec_prefix(&self) -> String {
        let first = self.outputs[0];
        if self.outputs.iter().all(|t| *t == first) {
            first.spec().to_string()
        } else {
            let names: Vec<&str> = self.outputs.iter().map(|t| t.spec()).collect();
            names.join(",")
        }
    }

    /// The specification, `TRANSFORMS+STAGE1`, when the inner compressor
    /// has one.
    pub fn spec(&self) -> Option<String> {
        Some(format!("{}+{}", self.spec_prefix(), self.inner.spec()?))
    }

    /// The floors, taken from `records` (their outputs), and the inner
    /// compressor prepared on the transformed records.
    ///
    /// # Errors
    /// A training sample outside a transform's domain (named by record,
    /// output and sample), an output with no value in the domain, or what
    /// preparing the inner compressor reports.
    pub(crate) fn prepared<'r>(
        &self,
        records: &[(ArrayView2<'r, f64>, ArrayView2<'r, f64>)],
    ) -> Result<Self> {
        let mut floors = vec![f64::INFINITY; self.outputs.len()];
        let mut transformed = Vec::with_capacity(records.len());
        for (r, (_, y)) in records.iter().enumerate() {
            let z = self.transform_strict(y.view()).map_err(|e| match e {
                CompressError::OutsideTransform {
                    signal,
                    index,
                    value,
                    transform,
                    domain,
                } => CompressError::OutsideTransform {
                    signal: format!("{signal} of training record {}", r + 1),
                    index,
                    value,
                    transform,
                    domain,
                },
                other => other,
            })?;
            for (j, floor) in floors.iter_mut().enumerate() {
                for &v in y.column(j) {
                    *floor = floor.min(v);
                }
            }
            transformed.push(z);
        }
        if let Some(j) = floors.iter().position(|f| !f.is_finite()) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "output transform",
                value: self.spec_prefix(),
                reason: format!(
                    "no training record to take the floor of {} from",
                    name("y", j, self.outputs.len())
                ),
            }));
        }
        let inner = if self.inner.records_to_prepare() > 0 {
            self.inner.prepared(
                records
                    .iter()
                    .zip(&transformed)
                    .map(|((u, _), z)| (u.view(), z.view())),
            )?
        } else {
            (*self.inner).clone()
        };
        Ok(Self {
            outputs: self.outputs.clone(),
            floors,
            inner: Box::new(inner),
        })
    }

    /// The outputs transformed, or the first sample outside a domain.
    fn transform_strict(&self, outputs: ArrayView2<'_, f64>) -> Result<ndarray::Array2<f64>> {
        self.check_width(outputs)?;
        let mut z = outputs.to_owned();
        for (j, (mut column, t)) in z.axis_iter_mut(Axis(1)).zip(&self.outputs).enumerate() {
            for (k, v) in column.iter_mut().enumerate() {
                if !t.accepts(*v) {
                    return Err(self.outside(j, k, *v));
                }
                *v = t.apply(*v);
            }
        }
        Ok(z)
    }

    fn outside(&self, output: usize, sample: usize, value: f64) -> CompressError {
        CompressError::OutsideTransform {
            signal: name("y", output, self.outputs.len()),
            index: sample,
            value,
            transform: self.outputs[output].spec(),
            domain: self.outputs[output].domain(),
        }
    }

    fn check_width(&self, outputs: ArrayView2<'_, f64>) -> Result<()> {
        if outputs.ncols() == self.outputs.len() {
            Ok(())
        } else {
            Err(CompressError::ShapeMismatch {
                inputs: 0,
                outputs: self.outputs.len(),
                got_inputs: 0,
                got_outputs: outputs.ncols(),
            })
        }
    }

    /// Transform `outputs` into the workspace's buffer (row-major), each
    /// sample through its output's transform; `floor` says what to do
    /// with a sample outside the domain: `None` refuses it, `Some` puts
    /// the output's floor in its place and lists it.
    fn transform_into(
        &self,
        outputs: ArrayView2<'_, f64>,
        buffer: &mut Vec<f64>,
        mut floored: Option<&mut Vec<FlooredSample>>,
    ) -> Result<()> {
        self.check_width(outputs)?;
        buffer.clear();
        for (k, row) in outputs.axis_iter(Axis(0)).enumerate() {
            for (j, (&v, t)) in row.iter().zip(&self.outputs).enumerate() {
                let v = match (&mut floored, t.accepts(v)) {
                    (_, true) => v,
                    // NaN and infinities are no sample at all: refused
                    // either way, as every compressor refuses them.
                    (Some(list), false) if v.is_finite() && self.is_prepared() => {
                        list.push(FlooredSample {
                            output: j,
                            sample: k,
                            value: v,
                        });
                        self.floors[j]
                    }
                    _ if !v.is_finite() => {
                        return Err(CompressError::NonFinite {
                            signal: name("y", j, self.outputs.len()),
                            index: k,
                            value: v,
                        });
                    }
                    _ => return Err(self.outside(j, k, v)),
                };
                buffer.push(t.apply(v));
            }
        }
        Ok(())
    }

    fn compress_with(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
        estimate_path: bool,
    ) -> Result<()> {
        let mut buffer = std::mem::take(&mut work.transformed);
        let mut floored = std::mem::take(&mut work.floored);
        let outcome = self
            .transform_into(outputs, &mut buffer, estimate_path.then_some(&mut floored))
            .and_then(|()| {
                let z = ArrayView2::from_shape(outputs.dim(), &buffer)
                    .unwrap_or_else(|_| unreachable!("one value per sample and output"));
                if estimate_path {
                    self.inner.compress_fast_into(inputs, z, work, alpha)
                } else {
                    self.inner.compress_into(inputs, z, work, alpha)
                }
            });
        work.transformed = buffer;
        work.floored = floored;
        outcome
    }
}

impl fmt::Display for Transformed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} of {} outputs", self.inner, self.spec_prefix())
    }
}

impl Compressor for Transformed {
    fn n_features(&self) -> usize {
        self.inner.n_features()
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.compress_with(inputs, outputs, work, alpha, false)
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.compress_with(inputs, outputs, work, alpha, true)
    }

    fn feature_names(&self) -> Vec<String> {
        self.inner.feature_names()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, array};

    fn log_ar1() -> CompressorConfig {
        let c: CompressorConfig = "log+ar:1".parse().unwrap();
        c.for_shape(0, 1, 50).unwrap()
    }

    /// The AR(1) of a decaying record's logarithms, against the closed
    /// form of a one-regressor least-squares fit.
    #[test]
    fn the_inner_compressor_sees_the_transformed_record() {
        let y = Array2::from_shape_fn((50, 1), |(k, _)| 5.0 * 0.9f64.powi(k as i32) + 0.01);
        let u = Array2::<f64>::zeros((50, 0));
        let c = log_ar1().prepared([(u.view(), y.view())]).unwrap();
        let logs = y.mapv(f64::ln);
        let ar: CompressorConfig = "ar:1".parse().unwrap();
        let ar = ar.for_shape(0, 1, 50).unwrap();
        let by_hand = ar.compress(u.view(), logs.view()).unwrap();
        // The AR(1) least-squares coefficient of z, by its closed form
        // sum z_k z_{k-1} / sum z_{k-1}^2.
        let z = logs.column(0);
        let closed = (1..50).map(|k| z[k] * z[k - 1]).sum::<f64>()
            / (1..50).map(|k| z[k - 1] * z[k - 1]).sum::<f64>();
        let got = c.compress(u.view(), y.view()).unwrap();
        assert!((got[0] - closed).abs() < 1e-12, "{got:?} vs {closed}");
        assert_eq!(got[0].to_bits(), by_hand[0].to_bits());
    }

    #[test]
    fn training_refuses_a_sample_outside_the_domain_and_estimates_floor_it() {
        let u = Array2::<f64>::zeros((50, 0));
        let good = Array2::from_shape_fn((50, 1), |(k, _)| 1.0 + (k % 7) as f64);
        let c = log_ar1().prepared([(u.view(), good.view())]).unwrap();
        let mut bad = good.clone();
        bad[[3, 0]] = -2.0;
        let e = c.compress(u.view(), bad.view()).unwrap_err();
        assert!(
            matches!(
                &e,
                CompressError::OutsideTransform {
                    index: 3,
                    transform: "log",
                    ..
                }
            ),
            "{e}"
        );
        let mut work = Workspace::new();
        let mut alpha = [0.0];
        c.compress_fast_into(u.view(), bad.view(), &mut work, &mut alpha)
            .unwrap();
        assert_eq!(
            work.floored_samples(),
            [FlooredSample {
                output: 0,
                sample: 3,
                value: -2.0
            }]
        );
        // The floor is the smallest training value: 1.0, so the estimate
        // sees the record with 1.0 at sample 3.
        let mut mended = good.clone();
        mended[[3, 0]] = 1.0;
        let mut want = [0.0];
        c.compress_fast_into(u.view(), mended.view(), &mut Workspace::new(), &mut want)
            .unwrap();
        assert_eq!(alpha[0].to_bits(), want[0].to_bits());
        // The next record is clean: the list is emptied.
        c.compress_fast_into(u.view(), good.view(), &mut work, &mut alpha)
            .unwrap();
        assert!(work.floored_samples().is_empty());
        // A NaN is refused on both paths.
        bad[[3, 0]] = f64::NAN;
        assert!(
            c.compress_fast_into(u.view(), bad.view(), &mut work, &mut alpha)
                .is_err()
        );
        // Preparing on a record with a zero names the record.
        let mut zero = good.clone();
        zero[[9, 0]] = 0.0;
        let e = log_ar1()
            .prepared([(u.view(), good.view()), (u.view(), zero.view())])
            .unwrap_err();
        assert!(e.to_string().contains("training record 2"), "{e}");
        assert!(e.to_string().contains("sample 9"), "{e}");
    }

    #[test]
    fn specifications_round_trip_and_shape_per_output() {
        let two: CompressorConfig = "log,log1p+pca:4".parse().unwrap();
        let shaped = two.for_shape(0, 2, 20).unwrap();
        assert_eq!(shaped.spec().as_deref(), Some("log,log1p+pca:4"));
        assert!(two.for_shape(0, 3, 20).is_err());
        let all: CompressorConfig = "log1p+ar:2".parse().unwrap();
        let CompressorConfig::Transformed(t) = all.for_shape(0, 3, 50).unwrap() else {
            panic!("a transformed compressor");
        };
        assert_eq!(t.transforms(), [SignalTransform::Log1p; 3]);
        assert!("log+log+ar:2".parse::<CompressorConfig>().is_err());
        assert!("sqrt+ar:2".parse::<CompressorConfig>().is_err());
        let y = array![[0.0], [3.0]];
        assert!(SignalTransform::Log1p.accepts(y[[0, 0]]));
        assert!(!SignalTransform::Log.accepts(y[[0, 0]]));
    }
}
