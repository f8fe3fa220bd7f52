//! The stage-1 choice as a serializable value, and its specification as
//! the command line and model files write it (`arx:5,5`, `pca:8`, ...).
//!
//! The compressors that wrap another configuration (an output transform,
//! a record's level appended) live here too: their types and
//! `CompressorConfig` hold each other.

mod learned;
mod level;
mod summary;
mod transform;

pub use learned::{ConvShape, LearnedShape, SummaryNetwork, WithLearned};
pub use level::WithLevel;
pub use summary::WithSummary;
pub use transform::{SignalTransform, TRANSFORM_RECORDS, Transformed};

use crate::InvalidSetting;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::error::{CompressError as Error, Result};
use crate::{Arx, Compressor, Linearized, Narx, OutputPca, RawRecord, Workspace, signal_rms};

/// The compression map g of stage 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum CompressorConfig {
    /// ARX(na, nb) least-squares coefficients, eq. (2).
    Arx(Arx),
    /// Polynomial NARX coefficients on scaled signals.
    Narx(Narx),
    /// Leading principal components of the output record (for models whose
    /// experiments all apply one input); fitted from the training design.
    Pca(OutputPca),
    /// The record itself, for very short records (`raw`).
    Raw(RawRecord),
    /// Output transforms (`log+`, `log1p+`...), then one of the above.
    Transformed(Transformed),
    /// One of the above, then each output's first sample and mean
    /// (`SPEC+level`).
    Leveled(WithLevel),
    /// One of the above, then each input's and output's mean, RMS, peak
    /// and mean frequency (`SPEC+summary`).
    Summarized(WithSummary),
    /// Another compressor's features (or none), then a trained summary
    /// network's (`SPEC+learned`, `learned`).
    Learned(WithLearned),
    /// The record regressed on its model's sensitivities at the prior's
    /// centre (`linearized`), for models whose equations the kernels hold.
    Linearized(Linearized),
}

/// Records a compressor's own parameters are fitted on: the first (up to)
/// 1000 training records for the output PCA's directions (more cost
/// without changing the leading directions); a NARX's signal scales take
/// [`NARX_SCALE_RECORDS`].
pub const PCA_RECORDS: usize = 1000;
/// Records a NARX's signal scales are measured on (see [`PCA_RECORDS`]).
pub const NARX_SCALE_RECORDS: usize = 32;

impl CompressorConfig {
    /// The same compressor for records of `n_inputs` inputs, `n_outputs`
    /// outputs and `n_samples` samples (the specifications `arx:5,5` and
    /// friends are written for one input and one output, `raw` for any).
    ///
    /// ```
    /// use twostage_compress::{Compressor, CompressorConfig};
    /// let ar: CompressorConfig = "ar:3".parse()?;
    /// // Output-only: three lags of each of two outputs.
    /// assert_eq!(ar.for_shape(0, 2, 100)?.n_features(), 6);
    /// let arx: CompressorConfig = "arx:2,2".parse()?;
    /// assert!(arx.for_shape(0, 1, 100).is_err());
    /// // The whole record: 10 samples of one output.
    /// let raw: CompressorConfig = "raw".parse()?;
    /// assert_eq!(raw.for_shape(0, 1, 10)?.n_features(), 10);
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`](crate::CompressError::InvalidSetting) for a shape the compressor cannot take: an
    /// ARX with input lags for a model without input, a NARX for more than
    /// one input or output.
    pub fn for_shape(&self, n_inputs: usize, n_outputs: usize, n_samples: usize) -> Result<Self> {
        let refuse = |reason: &str| {
            Error::InvalidSetting(InvalidSetting {
                name: "compressor",
                value: self.to_string(),
                reason: format!("{reason} ({n_inputs} input(s), {n_outputs} output(s))"),
            })
        };
        Ok(match self {
            Self::Arx(arx) if n_inputs == 0 && arx.nb() > 0 => {
                return Err(refuse(
                    "input lags need an input: for a model without input use ar:NA, an \
                     autoregression on the outputs",
                ));
            }
            Self::Arx(arx) => Self::Arx((*arx).with_signals(n_inputs, n_outputs)?),
            Self::Narx(_) if (n_inputs, n_outputs) != (1, 1) => {
                return Err(refuse("a NARX takes one input and one output"));
            }
            Self::Linearized(_) if (n_inputs, n_outputs) != (1, 1) => {
                return Err(refuse("the linearized car takes one input and one output"));
            }
            Self::Pca(pca) if pca.is_fitted() => Self::Pca(pca.clone().with_inputs(n_inputs)?),
            Self::Raw(_) => Self::Raw(RawRecord::new(n_samples, n_inputs, n_outputs)?),
            Self::Transformed(t) => Self::Transformed(t.shaped(
                n_outputs,
                t.inner().for_shape(n_inputs, n_outputs, n_samples)?,
            )?),
            Self::Leveled(l) => Self::Leveled(l.shaped(
                n_outputs,
                l.inner().for_shape(n_inputs, n_outputs, n_samples)?,
            )?),
            Self::Summarized(s) => Self::Summarized(WithSummary::new(
                s.inner().for_shape(n_inputs, n_outputs, n_samples)?,
                n_inputs,
                n_outputs,
            )?),
            Self::Learned(l) => Self::Learned(
                l.with_inner(
                    l.inner()
                        .map(|i| i.for_shape(n_inputs, n_outputs, n_samples))
                        .transpose()?,
                ),
            ),
            other => other.clone(),
        })
    }

    /// The specification the command line and model files write for this
    /// compressor (`arx:5,5`, `log+pca:8`...), when it has one (not for an
    /// ARX delay or NARX pure powers, which only the library sets).
    ///
    /// ```
    /// use twostage_compress::CompressorConfig;
    /// for spec in [
    ///     "arx:5,5", "ar:3", "narx:2,2,2", "pca:8", "raw", "log+ar:2", "log+arx:2,2+level",
    ///     "arx:2,2+summary", "arx:2,2+level+summary",
    /// ] {
    ///     let c: CompressorConfig = spec.parse()?;
    ///     assert_eq!(c.spec().as_deref(), Some(spec));
    /// }
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    pub fn spec(&self) -> Option<String> {
        match self {
            Self::Arx(arx) => arx.spec(),
            Self::Narx(narx) => narx.spec(),
            Self::Pca(pca) => Some(format!("pca:{}", pca.components())),
            Self::Raw(_) => Some("raw".into()),
            Self::Transformed(t) => t.spec(),
            Self::Leveled(l) => l.spec(),
            Self::Summarized(s) => s.spec(),
            Self::Learned(l) => l.spec(),
            Self::Linearized(l) => Some(l.spec()),
        }
    }

    /// The same compressor with its linearized part (if any, also inside
    /// the wrappers) shaped for the car `car` of prior box `[lower,
    /// upper]`, output noise variance `noise_variance`, sampled every
    /// `sample_time` s ([`Linearized::for_car`]); as it is without one.
    ///
    /// # Errors
    /// As [`Linearized::for_car`].
    pub fn for_car(
        &self,
        car: twostage_kernels::pacejka::Car,
        lower: [f64; 2],
        upper: [f64; 2],
        noise_variance: f64,
        sample_time: f64,
    ) -> Result<Self> {
        let inner = |c: &Self| c.for_car(car, lower, upper, noise_variance, sample_time);
        Ok(match self {
            Self::Linearized(l) => {
                Self::Linearized(l.for_car(car, lower, upper, noise_variance, sample_time)?)
            }
            Self::Leveled(l) => Self::Leveled(l.shaped(l.n_outputs(), inner(l.inner())?)?),
            Self::Summarized(s) => Self::Summarized(s.with_inner(inner(s.inner())?)?),
            Self::Learned(l) => Self::Learned(l.with_inner(l.inner().map(inner).transpose()?)),
            other => other.clone(),
        })
    }

    /// Whether a linearized part is in this stage 1 (shaped or not).
    ///
    /// ```
    /// use twostage_compress::CompressorConfig;
    /// let linearizes = |spec: &str| spec.parse::<CompressorConfig>().map(|c| c.linearizes());
    /// assert_eq!(linearizes("linearized+summary")?, true);
    /// assert_eq!(linearizes("arx:2,2+summary")?, false);
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    pub fn linearizes(&self) -> bool {
        match self {
            Self::Linearized(_) => true,
            Self::Transformed(t) => t.inner().linearizes(),
            Self::Leveled(l) => l.inner().linearizes(),
            Self::Summarized(s) => s.inner().linearizes(),
            Self::Learned(l) => l.inner().is_some_and(Self::linearizes),
            _ => false,
        }
    }

    /// Whether a linearized part still waits for its model's equations.
    pub fn needs_equations(&self) -> bool {
        match self {
            Self::Linearized(l) => l.car().is_none(),
            Self::Leveled(l) => l.inner().needs_equations(),
            Self::Summarized(s) => s.inner().needs_equations(),
            Self::Learned(l) => l.inner().is_some_and(Self::needs_equations),
            _ => false,
        }
    }

    /// Whether the outputs pass through transforms before stage 1, also
    /// inside the wrappers that append the level or the summary.
    ///
    /// ```
    /// use twostage_compress::CompressorConfig;
    /// for (spec, transforms) in [
    ///     ("arx:2,2", false),
    ///     ("log+arx:2,2", true),
    ///     ("log+arx:2,2+level", true),
    ///     ("log+arx:2,2+level+summary", true),
    ///     ("arx:2,2+summary", false),
    /// ] {
    ///     let c: CompressorConfig = spec.parse()?;
    ///     assert_eq!(c.transforms_outputs(), transforms, "{spec}");
    /// }
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    pub fn transforms_outputs(&self) -> bool {
        match self {
            Self::Transformed(_) => true,
            Self::Leveled(l) => l.inner().transforms_outputs(),
            Self::Summarized(s) => s.inner().transforms_outputs(),
            Self::Learned(l) => l.inner().is_some_and(Self::transforms_outputs),
            _ => false,
        }
    }

    /// How many training records [`CompressorConfig::prepared`] uses: 0
    /// when the compressor has nothing to fit.
    pub fn records_to_prepare(&self) -> usize {
        match self {
            CompressorConfig::Pca(pca) if !pca.is_fitted() => PCA_RECORDS,
            CompressorConfig::Narx(narx) if narx.has_unit_scales() => NARX_SCALE_RECORDS,
            CompressorConfig::Transformed(t) if !t.is_prepared() => {
                TRANSFORM_RECORDS.max(t.inner().records_to_prepare())
            }
            CompressorConfig::Leveled(l) => l.inner().records_to_prepare(),
            CompressorConfig::Summarized(s) => s.inner().records_to_prepare(),
            CompressorConfig::Learned(l) => l.inner().map_or(0, Self::records_to_prepare),
            _ => 0,
        }
    }

    /// The compressor with its unfitted parts fitted on `records` (each
    /// its inputs and outputs, a column per signal): an output PCA's
    /// directions, a NARX's signal scales (the RMS of each signal over the
    /// records); anything else as it is.
    ///
    /// # Errors
    /// What fitting the PCA or setting the scales reports (too few
    /// records, non-finite samples).
    pub fn prepared<'r>(
        &self,
        records: impl IntoIterator<Item = (ArrayView2<'r, f64>, ArrayView2<'r, f64>)>,
    ) -> Result<CompressorConfig> {
        let records: Vec<(ArrayView2<'r, f64>, ArrayView2<'r, f64>)> =
            records.into_iter().collect();
        Ok(match self {
            CompressorConfig::Pca(pca) if !pca.is_fitted() => {
                let take = records.len().min(PCA_RECORDS);
                let views: Vec<ArrayView2<'_, f64>> =
                    records[..take].iter().map(|(_, y)| y.view()).collect();
                let n_inputs = records.first().map_or(1, |(u, _)| u.ncols());
                CompressorConfig::Pca(pca.clone().fit(&views)?.with_inputs(n_inputs)?)
            }
            CompressorConfig::Narx(narx) if narx.has_unit_scales() => {
                let take = &records[..records.len().min(NARX_SCALE_RECORDS)];
                let rms = |signals: Vec<Vec<f64>>| -> Vec<f64> {
                    let width = signals.first().map_or(0, Vec::len);
                    (0..width)
                        .map(|j| {
                            (signals.iter().map(|s| s[j] * s[j]).sum::<f64>()
                                / signals.len() as f64)
                                .sqrt()
                        })
                        .collect()
                };
                let inputs = rms(take.iter().map(|(u, _)| signal_rms(u.view())).collect());
                let outputs = rms(take.iter().map(|(_, y)| signal_rms(y.view())).collect());
                CompressorConfig::Narx(narx.clone().with_scales(&inputs, &outputs)?)
            }
            CompressorConfig::Transformed(t) if !t.is_prepared() => {
                let take = records.len().min(TRANSFORM_RECORDS);
                CompressorConfig::Transformed(t.prepared(&records[..take])?)
            }
            CompressorConfig::Leveled(l) if l.inner().records_to_prepare() > 0 => {
                let n_outputs = records.first().map_or(1, |(_, y)| y.ncols());
                CompressorConfig::Leveled(WithLevel::new(l.inner().prepared(records)?, n_outputs)?)
            }
            CompressorConfig::Summarized(s) if s.inner().records_to_prepare() > 0 => {
                let (n_inputs, n_outputs) = records
                    .first()
                    .map_or((0, 1), |(u, y)| (u.ncols(), y.ncols()));
                CompressorConfig::Summarized(WithSummary::new(
                    s.inner().prepared(records)?,
                    n_inputs,
                    n_outputs,
                )?)
            }
            CompressorConfig::Learned(l)
                if l.inner().is_some_and(|i| i.records_to_prepare() > 0) =>
            {
                let inner = l.inner().map(|i| i.prepared(records)).transpose()?;
                CompressorConfig::Learned(l.with_inner(inner))
            }
            other => other.clone(),
        })
    }

    /// The summary network still to train, when this compressor learns
    /// one and has not yet: its architecture.
    ///
    /// ```
    /// use twostage_compress::CompressorConfig;
    /// let c: CompressorConfig = "arx:2,2+learned:4,4".parse()?;
    /// assert_eq!(c.untrained_summary().map(|s| s.channels.clone()), Some(vec![4, 4]));
    /// let arx: CompressorConfig = "arx:2,2".parse()?;
    /// assert!(arx.untrained_summary().is_none());
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    pub fn untrained_summary(&self) -> Option<&LearnedShape> {
        match self {
            Self::Learned(l) if l.network().is_none() => Some(l.shape()),
            _ => None,
        }
    }

    /// The same compressor with its summary network `network`.
    ///
    /// # Errors
    /// [`crate::CompressError::InvalidSetting`] for a compressor that
    /// learns no summary, or a network of other channels than it asks for.
    pub fn with_trained_summary(&self, network: SummaryNetwork) -> Result<Self> {
        match self {
            Self::Learned(l) => Ok(Self::Learned(l.clone().with_network(network)?)),
            other => Err(Error::InvalidSetting(InvalidSetting {
                name: "compressor",
                value: other.to_string(),
                reason: "only a `+learned` compressor takes a summary network".into(),
            })),
        }
    }
}

impl std::fmt::Display for CompressorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Arx(arx) => arx.fmt(f),
            Self::Narx(narx) => narx.fmt(f),
            Self::Pca(pca) => pca.fmt(f),
            Self::Raw(raw) => raw.fmt(f),
            Self::Transformed(t) => t.fmt(f),
            Self::Leveled(l) => l.fmt(f),
            Self::Summarized(s) => s.fmt(f),
            Self::Learned(l) => l.fmt(f),
            Self::Linearized(l) => l.fmt(f),
        }
    }
}

/// A wrapper's feature buffer cut into its inner compressor's `inner`
/// features and the `appended` ones after them (`+level`, `+summary`).
fn split_appended(
    alpha: &mut [f64],
    inner: usize,
    appended: usize,
) -> Result<(&mut [f64], &mut [f64])> {
    if alpha.len() != inner + appended {
        return Err(Error::InvalidSetting(InvalidSetting {
            name: "feature buffer",
            value: alpha.len().to_string(),
            reason: format!("{} features", inner + appended),
        }));
    }
    Ok(alpha.split_at_mut(inner))
}

/// Whole numbers separated by commas, exactly `count` of them.
fn counts(spec: &str, whole: &str, count: usize, what: &'static str) -> Result<Vec<usize>> {
    let values: Option<Vec<usize>> = spec.split(',').map(|v| v.trim().parse().ok()).collect();
    values.filter(|v| v.len() == count).ok_or_else(|| {
        Error::InvalidSetting(InvalidSetting {
            name: what,
            value: whole.to_string(),
            reason: format!(
                "the part after ':' must be {count} whole number(s) separated by commas"
            ),
        })
    })
}

impl std::str::FromStr for CompressorConfig {
    type Err = Error;

    /// A stage-1 specification as the command line and model files write
    /// it: `arx:NA,NB`, `ar:NA` (outputs only, for a model without input),
    /// `narx:NA,NB,DEG`, `pca:K`, or `raw` (the record itself, for very
    /// short records), each after output transforms when written
    /// `T+SPEC`: `T` is `id`, `log` or `log1p` for every output, or one per
    /// output separated by commas (`log+pca:8`, `log,id+ar:2`); then
    /// `+level`, `+summary` and, last, `+learned` (a summary network
    /// trained with the estimator, [`WithLearned`]), or `learned:C1,C2,..`
    /// alone.
    ///
    /// ```
    /// use twostage_compress::{Compressor, CompressorConfig};
    /// let arx: CompressorConfig = "arx:5,5".parse()?;
    /// assert_eq!(arx.n_features(), 10);
    /// assert!("arx:5".parse::<CompressorConfig>().is_err());
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    fn from_str(spec: &str) -> Result<Self> {
        let parsed = Self::parse_part(spec)?;
        if !matches!(parsed, Self::Learned(_)) && parsed.learns() {
            return Err(Error::InvalidSetting(InvalidSetting {
                name: "compressor",
                value: spec.to_string(),
                reason: "`+learned` comes last, after transforms, `+level` and `+summary` \
                         (e.g. log+arx:2,2+summary+learned)"
                    .into(),
            }));
        }
        Ok(parsed)
    }
}

impl CompressorConfig {
    /// Whether a summary network is part of this stage 1 (trained or not).
    ///
    /// ```
    /// use twostage_compress::CompressorConfig;
    /// let learns = |spec: &str| spec.parse::<CompressorConfig>().map(|c| c.learns());
    /// assert_eq!(learns("arx:2,2+summary+learned")?, true);
    /// assert_eq!(learns("arx:2,2+summary")?, false);
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    pub fn learns(&self) -> bool {
        match self {
            Self::Learned(_) => true,
            Self::Transformed(t) => t.inner().learns(),
            Self::Leveled(l) => l.inner().learns(),
            Self::Summarized(s) => s.inner().learns(),
            _ => false,
        }
    }

    /// One part of a specification, parsed (`from_str` checks the whole).
    fn parse_part(spec: &str) -> Result<Self> {
        const WHAT: &str = "compressor";
        if let Some(shape) = learned::parse_shape(spec) {
            return Ok(Self::Learned(WithLearned::new(None, shape?)?));
        }
        if let Some((inner, last)) = spec.trim().rsplit_once('+')
            && let Some(shape) = learned::parse_shape(last)
        {
            return Ok(Self::Learned(WithLearned::new(
                Some(inner.parse()?),
                shape?,
            )?));
        }
        if let Some(inner) = spec.trim().strip_suffix("+summary") {
            // Shaped by the model (`for_shape`): one input and output until then.
            return Ok(Self::Summarized(WithSummary::new(inner.parse()?, 1, 1)?));
        }
        if let Some(inner) = spec.trim().strip_suffix("+level") {
            // Shaped by the model (`for_shape`): one output until then.
            return Ok(Self::Leveled(WithLevel::new(inner.parse()?, 1)?));
        }
        if let Some((transforms, rest)) = spec.split_once('+') {
            let outputs = transforms
                .split(',')
                .map(str::parse::<SignalTransform>)
                .collect::<Result<Vec<_>>>()?;
            return Ok(Self::Transformed(Transformed::new(outputs, rest.parse()?)?));
        }
        if spec.trim() == "raw" {
            // Shaped by the model (`for_shape`): one sample of one output until then.
            return Ok(Self::Raw(RawRecord::new(1, 0, 1)?));
        }
        if spec.trim() == "linearized" {
            // Given its model's equations by `for_car`.
            return Ok(Self::Linearized(Linearized::new(
                crate::linearized::DEFAULT_SUBSTEPS,
            )?));
        }
        let (kind, orders) = spec.split_once(':').ok_or_else(|| {
            Error::InvalidSetting(InvalidSetting {
                name: WHAT,
                value: spec.to_string(),
                reason: "use arx:NA,NB, ar:NA (no input), narx:NA,NB,DEG, pca:K, raw, \
                     linearized[:S] or learned:C1,C2,.., after output transforms as log+SPEC"
                    .into(),
            })
        })?;
        Ok(match kind.trim() {
            "arx" => {
                let o = counts(orders, spec, 2, WHAT)?;
                Arx::new(o[0], o[1])?.into()
            }
            "narx" => {
                let o = counts(orders, spec, 3, WHAT)?;
                Narx::new(o[0], o[1], o[2])?.into()
            }
            "ar" => Arx::new(counts(orders, spec, 1, WHAT)?[0], 0)?.into(),
            "pca" => OutputPca::new(counts(orders, spec, 1, WHAT)?[0])?.into(),
            "linearized" => {
                let steps = counts(orders, spec, 1, WHAT)?[0];
                Self::Linearized(Linearized::new(u32::try_from(steps).unwrap_or(u32::MAX))?)
            }
            _ => {
                return Err(Error::InvalidSetting(InvalidSetting {
                    name: WHAT,
                    value: spec.to_string(),
                    reason: "use arx:NA,NB, ar:NA (no input), narx:NA,NB,DEG, pca:K, raw, \
                             linearized[:S] or learned:C1,C2,.."
                        .into(),
                }));
            }
        })
    }
}

impl From<Arx> for CompressorConfig {
    fn from(arx: Arx) -> Self {
        Self::Arx(arx)
    }
}

impl From<Narx> for CompressorConfig {
    fn from(narx: Narx) -> Self {
        Self::Narx(narx)
    }
}

impl From<OutputPca> for CompressorConfig {
    fn from(pca: OutputPca) -> Self {
        Self::Pca(pca)
    }
}

impl Compressor for CompressorConfig {
    fn n_features(&self) -> usize {
        match self {
            Self::Arx(c) => c.n_features(),
            Self::Narx(c) => c.n_features(),
            Self::Pca(c) => c.n_features(),
            Self::Raw(c) => c.n_features(),
            Self::Transformed(c) => c.n_features(),
            Self::Leveled(c) => c.n_features(),
            Self::Summarized(c) => c.n_features(),
            Self::Learned(c) => c.n_features(),
            Self::Linearized(c) => c.n_features(),
        }
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        match self {
            Self::Arx(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Narx(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Pca(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Raw(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Transformed(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Leveled(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Summarized(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Learned(c) => c.compress_into(inputs, outputs, work, alpha),
            Self::Linearized(c) => c.compress_into(inputs, outputs, work, alpha),
        }
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        // The list speaks of the record compressed last, whatever did it.
        work.floored.clear();
        match self {
            Self::Arx(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Narx(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Pca(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Raw(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Transformed(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Leveled(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Summarized(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Learned(c) => c.compress_fast_into(inputs, outputs, work, alpha),
            Self::Linearized(c) => c.compress_fast_into(inputs, outputs, work, alpha),
        }
    }

    fn feature_names(&self) -> Vec<String> {
        match self {
            Self::Arx(c) => c.feature_names(),
            Self::Narx(c) => c.feature_names(),
            Self::Pca(c) => c.feature_names(),
            Self::Raw(c) => c.feature_names(),
            Self::Transformed(c) => c.feature_names(),
            Self::Leveled(c) => c.feature_names(),
            Self::Summarized(c) => c.feature_names(),
            Self::Learned(c) => c.feature_names(),
            Self::Linearized(c) => c.feature_names(),
        }
    }
}
