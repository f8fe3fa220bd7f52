//! The trained estimator f = clip(h(g(u, y))).

use crate::InvalidSetting;
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;
use serde::Serialize;
use twostage_compress::{Compressor, Workspace};
use twostage_fit::Predictor;
use twostage_models::{
    FixedValues, InputDeviation, InputFamily, InputShapes, IoData, Marginal, ModelSpec,
    generic_signal_names,
};
use twostage_validate::{ConformalIntervals, ValidationReport};

use crate::adaptive::{AdaptiveIntervals, MIN_ADAPTIVE_CALIBRATION};
pub use crate::assessment::{Assessment, interval_in_box};
use crate::envelope::FeatureEnvelope;
use crate::error::{Error, Result};
use crate::space::{rows_to_estimates, to_estimate};
pub use crate::stored::{SignalNames, TrainingInfo};
use twostage_compress::CompressorConfig;
use twostage_fit::{FittedMixture, FittedRegressor};
pub use twostage_models::RecordShape;

/// Scratch space for [`Estimator::estimate_into`]: keep one per thread and
/// estimates allocate nothing.
#[derive(Debug, Default)]
pub struct EstimateWorkspace {
    compress: Workspace,
    features: Vec<f64>,
    /// Stage 2's whole output, where some of it is held
    /// ([`Estimator::holding`]).
    pub(crate) whole: Vec<f64>,
}

impl EstimateWorkspace {
    /// An empty workspace; it sizes itself on first use.
    pub fn new() -> Self {
        Self::default()
    }
}

/// A trained two-stage estimator: `theta_hat = clip(h(g(u, y)))`, explicit,
/// with no iteration and no tuning at estimate time.
///
/// Serialized (the file's payload, the JSON export) as its fields in this
/// order; files are read through the layouts of `layout.rs`, which check
/// them.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimator {
    pub(crate) param_names: Vec<String>,
    pub(crate) lower: Vec<f64>,
    pub(crate) upper: Vec<f64>,
    pub(crate) shape: RecordShape,
    pub(crate) compressor: CompressorConfig,
    pub(crate) regressor: FittedRegressor,
    pub(crate) training: TrainingInfo,
    /// Calibrated on their own fresh simulations, so they exist whether or
    /// not the estimator was also validated.
    pub(crate) intervals: Option<ConformalIntervals>,
    pub(crate) validation: Option<ValidationReport>,
    /// Where the training features lie (format version 2 on).
    pub(crate) envelope: Option<FeatureEnvelope>,
    /// Intervals whose width follows each record (format version 2 on).
    pub(crate) adaptive: Option<AdaptiveIntervals>,
    /// Each parameter's prior, whose transform the network learned in
    /// (format version 3 on; earlier files are uniform on the box).
    pub(crate) marginals: Vec<Marginal>,
    /// The names of the input and output signals, the columns `estimate`
    /// reads (format version 3 on; earlier files are `u`, `y`).
    pub(crate) signal_names: Option<SignalNames>,
    /// The family of inputs the held-out records spanned (format version
    /// 5 on): a record whose input lies outside is flagged.
    pub(crate) input_family: Option<InputFamily>,
    /// Where the held-out records' input shapes lie (format version 6
    /// on): a record whose input is of another shape is flagged.
    pub(crate) input_shapes: Option<InputShapes>,
    /// The parameters' conditional density given the features (format
    /// version 9 on, written only where there is one, so an estimator
    /// without keeps its bytes).
    pub(crate) posterior: Option<FittedMixture>,
    /// The model's parameters held at values, not estimated (format
    /// version 10 on, written only where there are any).
    pub(crate) fixed: FixedValues,
    /// Where some of the parameters stage 2 estimates are held at values
    /// at estimate time ([`Estimator::holding`]): the places, among stage
    /// 2's outputs, of those it reports. Never written: such an estimator
    /// is not saved.
    pub(crate) reported: Option<Vec<usize>>,
}

impl Serialize for Estimator {
    /// Its fields in order (the file's payload, the JSON export). The
    /// posterior and the values held close it and are written only where
    /// there are any, so that every estimator keeps the bytes of the
    /// oldest version that holds it (`layout.rs`); an estimator with
    /// values held writes its posterior's slot, empty or not, before them.
    fn serialize<S: serde::Serializer>(
        &self,
        serializer: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        if self.reported.is_some() {
            return Err(serde::ser::Error::custom(
                "an estimator with values held at estimate time is not saved: train one with \
                 --fix (Python: fix=) to keep the values in its file",
            ));
        }
        let mut fields = serializer.serialize_struct("Estimator", 17)?;
        fields.serialize_field("param_names", &self.param_names)?;
        fields.serialize_field("lower", &self.lower)?;
        fields.serialize_field("upper", &self.upper)?;
        fields.serialize_field("shape", &self.shape)?;
        fields.serialize_field("compressor", &self.compressor)?;
        fields.serialize_field("regressor", &self.regressor)?;
        fields.serialize_field("training", &self.training)?;
        fields.serialize_field("intervals", &self.intervals)?;
        fields.serialize_field("validation", &self.validation)?;
        fields.serialize_field("envelope", &self.envelope)?;
        fields.serialize_field("adaptive", &self.adaptive)?;
        fields.serialize_field("marginals", &self.marginals)?;
        fields.serialize_field("signal_names", &self.signal_names)?;
        fields.serialize_field("input_family", &self.input_family)?;
        fields.serialize_field("input_shapes", &self.input_shapes)?;
        if self.posterior.is_some() || !self.fixed.is_empty() {
            fields.serialize_field("posterior", &self.posterior)?;
        } else {
            fields.skip_field("posterior")?;
        }
        if self.fixed.is_empty() {
            fields.skip_field("fixed")?;
        } else {
            fields.serialize_field("fixed", &self.fixed)?;
        }
        fields.end()
    }
}

impl Estimator {
    /// Parameter names, in the order of theta.
    pub fn param_names(&self) -> &[String] {
        &self.param_names
    }
    /// Lower bounds of the prior box (estimates are clipped to it).
    pub fn lower(&self) -> &[f64] {
        &self.lower
    }
    /// Upper bounds of the prior box.
    pub fn upper(&self) -> &[f64] {
        &self.upper
    }
    /// Each parameter's prior (uniform on the box for files before format
    /// version 3).
    pub fn marginals(&self) -> &[Marginal] {
        &self.marginals
    }
    /// The names of the input and output signals (`u`, `y`, or `u1`, `u2`,
    /// ... for files before format version 3).
    pub fn signal_names(&self) -> SignalNames {
        self.signal_names.clone().unwrap_or_else(|| SignalNames {
            inputs: generic_signal_names("u", self.shape.n_inputs),
            outputs: generic_signal_names("y", self.shape.n_outputs),
        })
    }
    /// The model's parameters held at values (`--fix`): not estimated,
    /// put back in place wherever the estimator's model is simulated.
    pub fn fixed(&self) -> &FixedValues {
        &self.fixed
    }
    /// The estimator of a model whose parameters `fixed` were held at
    /// values while it trained ([`twostage_models::WithFixed`]).
    pub fn with_fixed(mut self, fixed: FixedValues) -> Self {
        self.fixed = fixed;
        self
    }
    /// The record shape it was trained on.
    pub fn record_shape(&self) -> &RecordShape {
        &self.shape
    }
    /// The family of inputs its held-out records spanned, when it knows
    /// one (trained on simulations, from format version 5 on).
    pub fn input_family(&self) -> Option<&InputFamily> {
        self.input_family.as_ref()
    }
    /// The density of the held-out records' input shapes, when it knows
    /// one (from format version 6 on, for a family whose inputs differ).
    pub fn input_shapes(&self) -> Option<&InputShapes> {
        self.input_shapes.as_ref()
    }
    /// The estimator judging records' inputs against `family` (the
    /// calibration and validation records' inputs, as training sets it):
    /// by its ranges, and by the density of its sample of input shapes.
    pub fn with_input_family(mut self, family: Option<InputFamily>) -> Self {
        let n_inputs = self.shape.n_inputs;
        let Some((family, sample)) = family
            .filter(|f| f.records() > 0 && f.is_consistent(n_inputs))
            .map(InputFamily::without_shape_sample)
        else {
            self.input_family = None;
            self.input_shapes = None;
            return self;
        };
        self.input_shapes = InputShapes::from_sample(&sample, n_inputs);
        self.input_family = Some(family);
        self
    }
    /// Why a record of `n_samples` gets no two-stage estimate from this
    /// estimator, and what to do instead; `None` for its own length. The
    /// estimate keeps the length the estimator was trained and validated
    /// on: its accuracy and intervals hold for no other.
    ///
    /// ```
    /// use twostage::{TwoStage, models::Benchmark};
    /// let est = TwoStage::builder(&Benchmark::new())
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(100).validation(0).calibration(0).train()?;
    /// assert!(est.length_refusal(1000).is_none());
    /// assert!(est.length_refusal(300).unwrap().contains("a window of 1000 samples"));
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn length_refusal(&self, n_samples: usize) -> Option<String> {
        let trained = self.shape.n_samples;
        (n_samples != trained).then(|| {
            format!(
                "{n_samples} samples; this estimator reads records of N = {trained}, as it was \
                 trained and validated: estimate a window of {trained} samples of it (cut the \
                 record, or a model file's [input] rows), train on records of {n_samples}, or \
                 refine through the model, which fits any length (`--refine` or \
                 `--refine=auto` on the command line, `Estimator.refine` in Python)"
            )
        })
    }
    /// The stage-1 compressor.
    pub fn compressor(&self) -> &CompressorConfig {
        &self.compressor
    }
    /// The fitted stage-2 map.
    pub fn regressor(&self) -> &FittedRegressor {
        &self.regressor
    }
    /// Training metadata.
    pub fn training(&self) -> &TrainingInfo {
        &self.training
    }
    /// The validation report, when validated.
    pub fn validation(&self) -> Option<&ValidationReport> {
        self.validation.as_ref()
    }
    /// Calibrated conformal intervals, when calibrated.
    pub fn intervals(&self) -> Option<&ConformalIntervals> {
        self.intervals.as_ref()
    }

    /// The `[[preset]]` block of a model file that trains this estimator's
    /// structure again (stage 1, stage 2 and the training size), named
    /// `name`; `None` when a stage has no specification (a structure only
    /// the library can set).
    ///
    /// ```
    /// # use twostage::TwoStage;
    /// # use twostage::models::Benchmark;
    /// # let model = Benchmark::builder().n_samples(200).build()?;
    /// let estimator = TwoStage::builder(&model)
    ///     .compressor("log1p+arx:2,2".parse::<twostage::CompressorConfig>()?)
    ///     .simulations(100).calibration(0).validation(0).linear(1e-6)?.train();
    /// // The benchmark's output goes negative: log1p refuses it, by sample.
    /// assert!(estimator.is_err());
    /// let estimator = TwoStage::builder(&model)
    ///     .compressor("arx:2,2".parse::<twostage::CompressorConfig>()?)
    ///     .regressor("mlp:3".parse()?)
    ///     .simulations(100).calibration(0).validation(0).train()?;
    /// let block = estimator.preset_block("mine").unwrap();
    /// assert!(block.contains("compress = \"arx:2,2\""), "{block}");
    /// assert!(block.contains("sims = 100"), "{block}");
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn preset_block(&self, name: &str) -> Option<String> {
        let compress = self.compressor.spec()?;
        let fit = self.training.regressor.spec()?;
        Some(format!(
            "[[preset]]\nname = \"{name}\"\ncompress = \"{compress}\"\nfit = \"{fit}\"\nsims = {}\n",
            self.training.simulations
        ))
    }

    /// The neighbourhood a refinement of this estimator's estimates
    /// searches (`twostage::Refinement`): `scale` times the calibrated
    /// intervals' half-widths, one radius per parameter. TS has already
    /// found the right region; the radius says how far its error goes.
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::Benchmark;
    /// let estimator = TwoStage::builder(&Benchmark::new())
    ///     .preset(twostage::paper_benchmark())
    ///     .simulations(300)
    ///     .validation(0)
    ///     .calibration(100)
    ///     .train()?;
    /// let radius = estimator.neighbourhood(2.0)?;
    /// let half = estimator.intervals().expect("calibrated").half_widths();
    /// assert_eq!(radius, [2.0 * half[0]]);
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// An estimator trained without calibration, or a scale that is not
    /// positive and finite.
    pub fn neighbourhood(&self, scale: f64) -> Result<Vec<f64>> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::InvalidSetting(InvalidSetting {
                name: "neighbourhood scale",
                value: scale.to_string(),
                reason: "a positive, finite multiple of the interval half-widths".into(),
            }));
        }
        let intervals = self.intervals().ok_or_else(|| {
            Error::InvalidSetting(InvalidSetting {
                name: "calibration",
                value: "0".into(),
                reason: "a refinement sizes its neighbourhood by the calibrated intervals: train \
                     with calibration > 0 (the command line's --calibrate)"
                    .into(),
            })
        })?;
        Ok(intervals.half_widths().iter().map(|w| scale * w).collect())
    }

    /// Estimate theta from one record (`inputs` N x n_u, `outputs` N x n_y)
    /// into `theta`: the hot path, allocation-free once `work` is warm.
    ///
    /// # Errors
    /// A record that cannot be compressed (wrong shape, non-finite samples,
    /// too short, degenerate), or a `theta` of the wrong length.
    pub fn estimate_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut EstimateWorkspace,
        theta: &mut [f64],
    ) -> Result<()> {
        if theta.len() != self.param_names.len() {
            return Err(Error::Record {
                what: "theta",
                found: theta.len(),
                expected: self.param_names.len(),
            });
        }
        self.features_of(inputs, outputs, work)?;
        let EstimateWorkspace {
            features, whole, ..
        } = work;
        self.stage2_into(features, whole, theta)?;
        to_estimate(theta, &self.marginals, &self.lower, &self.upper);
        Ok(())
    }

    /// Stage 1's features of one record (`inputs` N x n_u, `outputs`
    /// N x n_y), kept in `work`: what stage 2 and the posterior read.
    ///
    /// # Errors
    /// A record that cannot be compressed.
    pub fn features_of<'w>(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &'w mut EstimateWorkspace,
    ) -> Result<&'w [f64]> {
        let n = self.compressor.n_features();
        if work.features.len() != n {
            work.features.resize(n, 0.0);
        }
        self.compressor.compress_fast_into(
            inputs,
            outputs,
            &mut work.compress,
            &mut work.features,
        )?;
        Ok(&work.features)
    }

    /// Estimate theta from one SISO record.
    ///
    /// # Errors
    /// As [`Estimator::estimate_into`], and `u`, `y` of different lengths.
    pub fn estimate(&self, u: &[f64], y: &[f64]) -> Result<Vec<f64>> {
        let record = IoData::siso(u, y)?;
        self.estimate_record(&record)
    }

    /// Estimate theta from one record.
    ///
    /// # Errors
    /// As [`Estimator::estimate_into`].
    pub fn estimate_record(&self, record: &IoData) -> Result<Vec<f64>> {
        let mut theta = vec![0.0; self.param_names.len()];
        self.estimate_into(
            record.inputs(),
            record.outputs(),
            &mut EstimateWorkspace::new(),
            &mut theta,
        )?;
        Ok(theta)
    }

    /// Whether the estimator transforms its outputs before stage 1 (then
    /// [`Assessment::floored_samples`] says which samples it could not
    /// take as they were).
    pub fn transforms_outputs(&self) -> bool {
        self.compressor.transforms_outputs()
    }

    /// The adaptive intervals, when calibrated.
    pub fn adaptive_intervals(&self) -> Option<&AdaptiveIntervals> {
        self.adaptive.as_ref()
    }

    /// The feature envelope of the training chart, when it has one.
    pub fn envelope(&self) -> Option<&FeatureEnvelope> {
        self.envelope.as_ref()
    }

    /// Estimate theta from one record, with its intervals and whether the
    /// record lies outside what training saw.
    ///
    /// ```
    /// # use twostage::TwoStage;
    /// # use twostage::models::{Benchmark, IoData, Simulator, experiment_rng};
    /// # let model = Benchmark::builder().n_samples(300).build()?;
    /// # let estimator = TwoStage::builder(&model).simulations(300).validation(0).calibration(100).linear(1e-6)?.train()?;
    /// let mut record = model.spec().new_record();
    /// model.simulate(&[0.2], &mut experiment_rng(4, 0), &mut record)?;
    /// assert!(!estimator.assess(&record)?.out_of_distribution());
    /// // The same input with a tenfold output: no benchmark system does that.
    /// let y: Vec<f64> = record.output(0).iter().map(|v| 10.0 * v).collect();
    /// let alien = IoData::siso(record.input(0), &y)?;
    /// assert!(estimator.assess(&alien)?.out_of_distribution());
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// As [`Estimator::estimate_into`].
    pub fn assess(&self, record: &IoData) -> Result<Assessment> {
        self.assess_with(
            record.inputs(),
            record.outputs(),
            &mut EstimateWorkspace::new(),
        )
    }

    /// [`Estimator::assess`] of the record `inputs` (N x n_u), `outputs`
    /// (N x n_y), with a workspace kept across records.
    ///
    /// # Errors
    /// As [`Estimator::estimate_into`].
    pub fn assess_with(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut EstimateWorkspace,
    ) -> Result<Assessment> {
        let mut theta = vec![0.0; self.param_names.len()];
        self.estimate_into(inputs, outputs, work, &mut theta)?;
        let mut assessment = self.assessment_of(theta, &work.features, inputs)?;
        assessment.floored_samples = work.compress.floored_samples().to_vec();
        Ok(assessment)
    }

    /// What the runtime's sliding window of `window` samples
    /// (`twostage_runtime::Stream::window`) says after the last sample of
    /// `record`: the same as [`Estimator::assess`] of the window's samples
    /// alone, except for a linearized stage 1, whose car runs from the
    /// record's first sample and whose window spans whole blocks of a
    /// tenth of it ([`twostage_compress::Linearized::compress_window`]).
    /// The input's family and shape are judged on the last `window`
    /// samples; `window` 0 is the whole record.
    ///
    /// ```
    /// # use twostage::{TwoStage, models::{Benchmark, Simulator, experiment_rng}};
    /// # let model = Benchmark::builder().n_samples(200).build()?;
    /// # let trained = TwoStage::builder(&model).simulations(300).validation(0)
    /// #     .calibration(100).linear(1e-6)?.train()?;
    /// # let mut record = model.spec().new_record();
    /// # model.simulate(&[0.4], &mut experiment_rng(1, 0), &mut record)?;
    /// let last = trained.assess_window(&record, 100)?;
    /// assert_eq!(last, trained.assess(&record.window(100, 200))?);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// As [`Estimator::assess`].
    pub fn assess_window(&self, record: &IoData, window: usize) -> Result<Assessment> {
        let n = record.n_samples();
        let start = if window == 0 {
            0
        } else {
            n.saturating_sub(window)
        };
        let last = record.window(start, n);
        let CompressorConfig::Linearized(linearized) = &self.compressor else {
            return self.assess(&last);
        };
        let mut features = vec![0.0; self.compressor.n_features()];
        linearized.compress_window(record.inputs(), record.outputs(), window, &mut features)?;
        let mut theta = vec![0.0; self.param_names.len()];
        self.stage2_into(&features, &mut Vec::new(), &mut theta)?;
        to_estimate(&mut theta, &self.marginals, &self.lower, &self.upper);
        self.assessment_of(theta, &features, last.inputs())
    }

    /// The assessment of the estimate `theta` of stage 1's `features`
    /// from a record whose inputs are `inputs`: its intervals, distance
    /// and input judged (no floored samples: the caller knows them).
    fn assessment_of(
        &self,
        theta: Vec<f64>,
        features: &[f64],
        inputs: ArrayView2<'_, f64>,
    ) -> Result<Assessment> {
        let adaptive_half_widths = match &self.adaptive {
            Some(a) => {
                let mut widths = vec![0.0; a.n_parameters()];
                a.half_widths_into(features, &mut widths)?;
                Some(self.reported_of(widths))
            }
            None => None,
        };
        Ok(Assessment {
            theta,
            adaptive_half_widths,
            half_widths: self.intervals.as_ref().map(|c| c.half_widths().to_vec()),
            feature_distance: self.envelope.as_ref().map(|e| e.distance(features)),
            distance_threshold: self.envelope.as_ref().map(FeatureEnvelope::threshold),
            floored_samples: Vec::new(),
            input_deviations: self.input_deviations(inputs),
            input_shape_distance: self.input_shape_distance(inputs),
            input_shape_threshold: self.input_shapes.as_ref().map(InputShapes::threshold),
        })
    }

    /// How a record's inputs (N x n_u) lie outside the estimator's input
    /// family, each named by the input's name (empty inside it, and for an
    /// estimator without a family): what [`Estimator::assess`] reports.
    pub fn input_deviations(&self, inputs: ArrayView2<'_, f64>) -> Vec<InputDeviation> {
        let Some(family) = &self.input_family else {
            return Vec::new();
        };
        let columns: Vec<Vec<f64>> = inputs.columns().into_iter().map(|c| c.to_vec()).collect();
        let signals: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        family.signal_deviations(&signals, &self.signal_names().inputs)
    }

    /// How far the shape of a record's inputs (N x n_u) lies from the
    /// held-out records' input shapes; `None` for an estimator that does
    /// not know them.
    pub fn input_shape_distance(&self, inputs: ArrayView2<'_, f64>) -> Option<f64> {
        let shapes = self.input_shapes.as_ref()?;
        let columns: Vec<Vec<f64>> = inputs.columns().into_iter().map(|c| c.to_vec()).collect();
        let signals: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        Some(shapes.distance(&signals))
    }

    /// Estimate theta for many records in parallel; each record gets its
    /// own result, so one bad record does not stop the others.
    pub fn estimate_batch(&self, records: &[IoData]) -> Vec<Result<Vec<f64>>> {
        records
            .par_iter()
            .map_init(EstimateWorkspace::new, |work, record| {
                let mut theta = vec![0.0; self.param_names.len()];
                self.estimate_into(record.inputs(), record.outputs(), work, &mut theta)
                    .map(|()| theta)
            })
            .collect()
    }

    /// Estimates for every row of a compressed chart's features (out of the
    /// learning space, clipped).
    ///
    /// ```
    /// # use twostage::{TwoStage, models::Benchmark};
    /// # let model = Benchmark::builder().n_samples(200).build()?;
    /// # let estimator = TwoStage::builder(&model).simulations(100).validation(0).calibration(0).linear(1e-6)?.train()?;
    /// use twostage::compress::Compressor;
    /// let features = ndarray::Array2::zeros((3, estimator.compressor().n_features()));
    /// let estimates = estimator.predict_features(features.view())?;
    /// assert_eq!(estimates.dim(), (3, 1));
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// Features of another width than the compressor writes.
    pub fn predict_features(&self, features: ArrayView2<'_, f64>) -> Result<Array2<f64>> {
        let mut out = self.regressor.predict(features)?;
        if let Some(reported) = &self.reported {
            out = out.select(ndarray::Axis(1), reported);
        }
        rows_to_estimates(&mut out, &self.marginals, &self.lower, &self.upper);
        Ok(out)
    }

    /// Stage 2's estimate of `features` (in the learning space) into
    /// `theta`: its reported outputs, `whole` holding all of them where
    /// some are held.
    fn stage2_into(&self, features: &[f64], whole: &mut Vec<f64>, theta: &mut [f64]) -> Result<()> {
        let Some(reported) = &self.reported else {
            self.regressor.predict_into(features, theta)?;
            return Ok(());
        };
        whole.resize(self.regressor.n_outputs(), 0.0);
        self.regressor.predict_into(features, whole)?;
        for (t, &j) in theta.iter_mut().zip(reported) {
            *t = whole[j];
        }
        Ok(())
    }

    /// The reported parameters' entries of `values`, one per stage 2
    /// output.
    fn reported_of(&self, values: Vec<f64>) -> Vec<f64> {
        match &self.reported {
            Some(reported) => reported.iter().map(|&j| values[j]).collect(),
            None => values,
        }
    }
}

/// Building an estimator out of its fitted stages, then calibrating and
/// validating it on held-out records: the steps every training ends with.
impl Estimator {
    /// The estimator of `spec`'s parameters made of the fitted stages,
    /// before calibration and validation: no intervals, no report, and the
    /// envelope of the features it was fitted on (`trained_on`).
    ///
    /// ```
    /// use twostage::{Estimator, TrainingInfo, RegressorConfig};
    /// use twostage::compress::Arx;
    /// use twostage::fit::Ridge;
    /// use twostage::models::{Benchmark, Simulator};
    ///
    /// let model = Benchmark::builder().n_samples(100).build()?;
    /// let compressor = twostage::CompressorConfig::from(Arx::new(1, 1)?);
    /// let features = ndarray::Array2::from_shape_fn((30, 2), |(i, j)| (i * (j + 1)) as f64);
    /// let thetas = ndarray::Array2::from_shape_fn((30, 1), |(i, _)| i as f64 / 40.0);
    /// let config = RegressorConfig::Linear(Ridge::new(1e-6)?);
    /// let fitted = config.fit(features.view(), thetas.view(), 1)?;
    /// let training = TrainingInfo {
    ///     model: model.spec().name().to_string(),
    ///     simulations: 30,
    ///     failures: 0,
    ///     seed: 1,
    ///     sampling: "Random".into(),
    ///     regressor: config,
    ///     version: "0.1.0".into(),
    /// };
    /// let estimator = Estimator::from_stages(model.spec(), compressor, fitted, training, features.view());
    /// assert!(estimator.intervals().is_none() && estimator.validation().is_none());
    /// # Ok::<(), twostage::Error>(())
    /// ```
    pub fn from_stages(
        spec: &ModelSpec,
        compressor: CompressorConfig,
        regressor: FittedRegressor,
        training: TrainingInfo,
        trained_on: ArrayView2<'_, f64>,
    ) -> Self {
        let prior = spec.prior();
        Self {
            param_names: spec.param_names().to_vec(),
            lower: prior.lower().to_vec(),
            upper: prior.upper().to_vec(),
            shape: spec.record_shape(),
            compressor,
            regressor,
            training,
            intervals: None,
            validation: None,
            envelope: FeatureEnvelope::fit(trained_on),
            adaptive: None,
            marginals: prior.marginals().to_vec(),
            signal_names: Some(SignalNames {
                inputs: spec.input_names().to_vec(),
                outputs: spec.output_names().to_vec(),
            }),
            input_family: None,
            input_shapes: None,
            posterior: None,
            fixed: FixedValues::default(),
            reported: None,
        }
    }

    /// Calibrate the intervals at miscoverage `alpha` on held-out records,
    /// given by their true parameters and their features: conformal
    /// intervals always, feature-adaptive ones from 100 records on (fitted
    /// with `seed`), and the out-of-distribution envelope's threshold.
    ///
    /// # Errors
    /// An `alpha` outside (0, 1), or an adaptive fit that fails.
    pub fn calibrate(
        &mut self,
        truth: ArrayView2<'_, f64>,
        features: ArrayView2<'_, f64>,
        alpha: f64,
        seed: u64,
    ) -> Result<()> {
        let estimates = self.predict_features(features)?;
        let residuals = &truth - &estimates;
        if let Some(envelope) = self.envelope.as_mut() {
            envelope.recalibrate(features);
        }
        if residuals.nrows() >= MIN_ADAPTIVE_CALIBRATION {
            self.adaptive = Some(AdaptiveIntervals::calibrate(
                features,
                residuals.view(),
                alpha,
                seed,
            )?);
        }
        self.intervals = Some(ConformalIntervals::calibrate(residuals.view(), alpha)?);
        Ok(())
    }

    /// Validate on held-out records that calibration did not see, given by
    /// their true parameters and their features: the report of Theorem 1
    /// with confidence `1 - delta`, and the coverage of the intervals
    /// calibrated before.
    ///
    /// # Errors
    /// A `delta` outside (0, 1), or records of another width.
    pub fn validate(
        &mut self,
        truth: ArrayView2<'_, f64>,
        features: ArrayView2<'_, f64>,
        delta: f64,
    ) -> Result<()> {
        let estimates = self.predict_features(features)?;
        if let Some(adaptive) = self.adaptive.as_mut() {
            adaptive.validate(features, (&truth - &estimates).view())?;
        }
        self.validation = Some(ValidationReport::new(
            &self.param_names,
            truth,
            estimates.view(),
            &self.lower,
            &self.upper,
            delta,
            self.intervals.clone(),
        )?);
        Ok(())
    }
}
