//! `Estimator::to_runtime`: the blob the no_std runtime reads in place
//! (layout: [`twostage_runtime::format`]).

use twostage_compress::Compressor;
use twostage_fit::{FittedLinear, FittedMixture, FittedMlp, Predictor, Standardizer, Support};
use twostage_kernels::linearized::CarLinearization;
use twostage_models::{InputFamily, Transform};
use twostage_runtime::format::{
    CHECKSUM_FROM, FLAG_ADAPTIVE, FLAG_CONFORMAL, FLAG_ENVELOPE, FLAG_INPUT_FAMILY,
    FLAG_LEARNED_SUMMARY, FLAG_LINEARIZED, FLAG_OUTPUT_TRANSFORMS, FLAG_POSTERIOR,
    FLAG_SIGNAL_SUMMARY, HEADER_BYTES, MAGIC, MAX_CHANNELS, MAX_COMPONENTS, MAX_EXPERTS,
    MAX_KERNEL, MAX_LAYERS, MAX_MEMBERS, MAX_ORDER, MAX_PARAMETERS, MAX_SIGNALS, MAX_SIZES,
    MAX_WIDTH, REGRESSOR_NETWORK, REGRESSOR_PIECEWISE, SIGNAL_IDENTITY, SIGNAL_LOG, SIGNAL_LOG1P,
    SUPPORT_INTERVAL, SUPPORT_POSITIVE, SUPPORT_REAL, TRANSFORM_IDENTITY, TRANSFORM_LOG, VERSION,
    VERSION_WITHOUT_FAMILY, VERSION_WITHOUT_LEARNED, VERSION_WITHOUT_LINEARIZED,
    VERSION_WITHOUT_POSTERIOR, VERSION_WITHOUT_SUMMARY,
};

use crate::error::{Error, Result};
use crate::estimator::Estimator;
use twostage_compress::{Arx, CompressorConfig, SignalTransform, SummaryNetwork, Transformed};
use twostage_fit::FittedRegressor;

/// Little-endian sections, each starting at a multiple of 8 bytes.
struct Writer {
    bytes: Vec<u8>,
}

impl Writer {
    fn u32(&mut self, v: usize) -> Result<()> {
        let v = u32::try_from(v).map_err(|_| refuse(format!("the count {v} exceeds 32 bits")))?;
        self.bytes.extend_from_slice(&v.to_le_bytes());
        Ok(())
    }
    fn u32s(&mut self, values: &[usize]) -> Result<()> {
        for v in values {
            self.u32(*v)?;
        }
        while !self.bytes.len().is_multiple_of(8) {
            self.bytes.push(0);
        }
        Ok(())
    }
    fn f64s(&mut self, values: &[f64]) {
        for v in values {
            self.bytes.extend_from_slice(&v.to_le_bytes());
        }
    }

    /// A network with its standardizations; `members` are its ensemble.
    fn network(
        &mut self,
        sizes: &[usize],
        features: &Standardizer,
        targets: &Standardizer,
        members: &[Vec<f64>],
    ) -> Result<()> {
        if sizes.len() > MAX_SIZES || sizes.iter().any(|w| *w > MAX_WIDTH) {
            return Err(refuse(format!(
                "the network {sizes:?} exceeds the runtime's {} layers of at most {MAX_WIDTH} \
                 units",
                MAX_SIZES - 2
            )));
        }
        if members.len() > MAX_MEMBERS {
            return Err(refuse(format!(
                "{} ensemble members, the runtime takes at most {MAX_MEMBERS}",
                members.len()
            )));
        }
        self.u32(sizes.len())?;
        self.u32(members.len())?;
        self.u32s(sizes)?;
        self.f64s(features.mean());
        self.f64s(features.scale());
        self.f64s(targets.mean());
        self.f64s(targets.scale());
        for member in members {
            self.f64s(member);
        }
        Ok(())
    }

    fn mlp(&mut self, mlp: &FittedMlp) -> Result<()> {
        self.network(
            mlp.sizes(),
            mlp.feature_scaling(),
            mlp.target_scaling(),
            mlp.members(),
        )
    }

    /// A linear map is a network without hidden layer and with zero biases.
    fn linear(&mut self, linear: &FittedLinear) -> Result<()> {
        let (n, q) = (linear.n_inputs(), linear.n_outputs());
        let mut member = linear.weights().to_vec();
        member.extend(std::iter::repeat_n(0.0, q));
        self.network(
            &[n, q],
            linear.feature_scaling(),
            linear.target_scaling(),
            &[member],
        )
    }
}

impl Writer {
    /// Each output's transform code, then its floor.
    fn output_transforms(&mut self, transformed: &Transformed, n_outputs: usize) -> Result<()> {
        let (codes, floors) = (transformed.transforms(), transformed.floors());
        if codes.len() != n_outputs || floors.len() != n_outputs {
            return Err(refuse(format!(
                "{} output transforms with {} floors for {n_outputs} outputs: the estimator's \
                 compressor was not prepared on its training records; train it again",
                codes.len(),
                floors.len()
            )));
        }
        let codes: Vec<usize> = codes
            .iter()
            .map(|t| match t {
                SignalTransform::Identity => SIGNAL_IDENTITY as usize,
                SignalTransform::Log => SIGNAL_LOG as usize,
                SignalTransform::Log1p => SIGNAL_LOG1P as usize,
            })
            .collect();
        self.u32s(&codes)?;
        self.f64s(floors);
        Ok(())
    }
}

impl Writer {
    /// The learned stage 1's shapes (channels out, kernel, stride per
    /// layer), each signal's scale, then the weights.
    fn learned(&mut self, network: &SummaryNetwork) -> Result<()> {
        let layers = network.layers();
        let beyond = layers.len() > MAX_LAYERS
            || network.n_signals() > MAX_CHANNELS
            || layers
                .iter()
                .any(|l| l.outputs > MAX_CHANNELS || l.kernel > MAX_KERNEL);
        if beyond {
            return Err(refuse(format!(
                "a summary network of {} layers over {} signals ({:?}): the runtime takes at \
                 most {MAX_LAYERS} layers of {MAX_CHANNELS} channels over {MAX_CHANNELS} \
                 signals, kernels of at most {MAX_KERNEL} samples; train a smaller \
                 `+learned:C,..`",
                layers.len(),
                network.n_signals(),
                layers
            )));
        }
        let mut shapes = vec![layers.len()];
        for l in layers {
            shapes.extend([l.outputs, l.kernel, l.stride]);
        }
        self.u32s(&shapes)?;
        self.f64s(network.scales());
        self.f64s(network.weights());
        Ok(())
    }
}

/// What the runtime streams as stage 1: the ARX, an output transform in
/// front of it, each signal's summary after it, a summary network after
/// them; or the car linearized, alone.
struct RuntimeStage1<'e> {
    transformed: Option<&'e Transformed>,
    arx: Option<&'e Arx>,
    summary: bool,
    learned: Option<&'e SummaryNetwork>,
    linearized: Option<&'e CarLinearization>,
}

fn refuse(reason: String) -> Error {
    Error::NotExportable { reason }
}

impl Estimator {
    /// The estimator as a blob for the microcontroller runtime
    /// ([`twostage_runtime`]): versioned, checksummed, read in place. The
    /// runtime streams ARX and AR compressors; stage 2 may be any of the
    /// project's (linear, MLP, piecewise), with the intervals and the
    /// envelope; the car linearized (`linearized`) streams too; output
    /// transforms (`log+arx:...`) go with the ARX, and
    /// so does each signal's summary after it (`arx:...+summary`), but
    /// not both; a learned summary (`arx:...[+summary]+learned`) closes
    /// the features, without output transforms.
    ///
    /// ```
    /// use twostage::TwoStage;
    /// use twostage::models::Benchmark;
    /// let estimator = TwoStage::builder(&Benchmark::builder().n_samples(200).build()?)
    ///     .simulations(300).validation(0).calibration(100).linear(1e-6)?.train()?;
    /// let blob = estimator.to_runtime()?;
    /// let runtime = twostage::runtime::Estimator::from_bytes(&blob)?;
    /// assert_eq!(runtime.n_parameters(), 1);
    /// assert!(runtime.has_intervals() && runtime.has_envelope());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::NotExportable`] for a NARX, PCA or raw compressor, a
    /// learned summary without ARX coefficients before it, a summary
    /// after output transforms, or sizes beyond the runtime's limits
    /// ([`twostage_runtime::format`]).
    pub fn to_runtime(&self) -> Result<Vec<u8>> {
        if self.holds_at_estimate_time() {
            return Err(Error::NotExportable {
                reason: "values held at estimate time are not exported: train with --fix \
                         (Python: fix=) to hold them on the control unit"
                    .into(),
            });
        }
        let stage1 = self.runtime_stage1()?;
        let mut w = Writer {
            bytes: Vec::with_capacity(4096),
        };
        w.bytes.extend_from_slice(&MAGIC);
        let version = if self.posterior.is_some() {
            VERSION
        } else if stage1.linearized.is_some() {
            VERSION_WITHOUT_POSTERIOR
        } else if stage1.learned.is_some() {
            VERSION_WITHOUT_LINEARIZED
        } else if stage1.summary {
            VERSION_WITHOUT_LEARNED
        } else if self.runtime_family().is_some() {
            VERSION_WITHOUT_SUMMARY
        } else {
            VERSION_WITHOUT_FAMILY
        };
        w.u32(version as usize)?;
        w.u32(0)?; // length, set below
        w.u32(0)?; // checksum, set below
        w.header(self, &stage1)?;
        w.parts(self, &stage1)?;
        debug_assert_eq!(self.compressor.n_features(), self.regressor.n_inputs());
        let length = w.bytes.len();
        let length = u32::try_from(length)
            .map_err(|_| refuse(format!("{length} bytes exceed the format's 4 GiB")))?;
        w.bytes[8..12].copy_from_slice(&length.to_le_bytes());
        let crc = twostage_runtime::format::checksum(&w.bytes[CHECKSUM_FROM..]);
        w.bytes[12..16].copy_from_slice(&crc.to_le_bytes());
        Ok(w.bytes)
    }

    /// The input family the runtime judges records by: one of some
    /// records, of at least one input.
    fn runtime_family(&self) -> Option<&InputFamily> {
        self.input_family
            .as_ref()
            .filter(|f| f.records() > 0 && f.n_inputs() > 0)
    }

    /// The ARX stage 1 the runtime streams, the output transform in front
    /// of it where there is one, whether each signal's summary follows
    /// it, and the summary network after them; refused beyond the
    /// runtime's sizes.
    fn runtime_stage1(&self) -> Result<RuntimeStage1<'_>> {
        if let CompressorConfig::Linearized(l) = &self.compressor {
            let car = l.car().ok_or_else(|| {
                refuse(format!(
                    "{} is not shaped for a model: train the estimator first",
                    self.compressor
                ))
            })?;
            return Ok(RuntimeStage1 {
                transformed: None,
                arx: None,
                summary: false,
                learned: None,
                linearized: Some(car),
            });
        }
        let (learned, before) = match &self.compressor {
            CompressorConfig::Learned(l) => {
                let network = l.network().ok_or_else(|| {
                    refuse(format!(
                        "the summary network of {} is untrained: train the estimator first",
                        self.compressor
                    ))
                })?;
                let inner = l.inner().ok_or_else(|| {
                    refuse(format!(
                        "the runtime streams a learned summary after ARX coefficients, this \
                         estimator uses {} alone; train with --compress arx:NA,NB+learned",
                        self.compressor
                    ))
                })?;
                (Some(network), inner)
            }
            other => (None, other),
        };
        let (summary, stage1) = match before {
            CompressorConfig::Summarized(s) => (true, s.inner()),
            other => (false, other),
        };
        let (transformed, stage1) = match stage1 {
            CompressorConfig::Transformed(t) if !summary && learned.is_none() => {
                (Some(t), t.inner())
            }
            other => (None, other),
        };
        let CompressorConfig::Arx(arx) = stage1 else {
            return Err(refuse(format!(
                "the runtime streams ARX and AR compressors, with each signal's summary or a \
                 learned summary after them or output transforms before them, and the car \
                 linearized; this estimator uses {}; train with --compress arx:NA,NB (or \
                 ar:NA, log+arx:NA,NB, arx:NA,NB+summary, arx:NA,NB+summary+learned, \
                 linearized)",
                self.compressor
            )));
        };
        let q = self.param_names.len();
        let shape = &self.shape;
        if q > MAX_PARAMETERS
            || shape.n_inputs > MAX_SIGNALS
            || shape.n_outputs > MAX_SIGNALS
            || arx.na().max(arx.nb()).max(arx.delay()) > MAX_ORDER
        {
            return Err(refuse(format!(
                "{q} parameters, {} inputs, {} outputs and {arx}: the runtime takes at most \
                 {MAX_PARAMETERS} parameters, {MAX_SIGNALS} signals each way and orders up \
                 to {MAX_ORDER}",
                shape.n_inputs, shape.n_outputs
            )));
        }
        Ok(RuntimeStage1 {
            transformed,
            arx: Some(arx),
            summary,
            learned,
            linearized: None,
        })
    }
}

impl Writer {
    /// The header's fields after the magic, version, length and checksum:
    /// sizes, the ARX orders, the flags of the optional parts, the kind of
    /// stage 2.
    fn header(&mut self, e: &Estimator, stage1: &RuntimeStage1<'_>) -> Result<()> {
        let mut flags = 0;
        if e.intervals.is_some() {
            flags |= FLAG_CONFORMAL;
        }
        if e.adaptive.is_some() {
            flags |= FLAG_ADAPTIVE;
        }
        if e.envelope.is_some() {
            flags |= FLAG_ENVELOPE;
        }
        if stage1.transformed.is_some() {
            flags |= FLAG_OUTPUT_TRANSFORMS;
        }
        if e.runtime_family().is_some() {
            flags |= FLAG_INPUT_FAMILY;
        }
        if stage1.summary {
            flags |= FLAG_SIGNAL_SUMMARY;
        }
        if stage1.learned.is_some() {
            flags |= FLAG_LEARNED_SUMMARY;
        }
        if stage1.linearized.is_some() {
            flags |= FLAG_LINEARIZED;
        }
        if e.posterior.is_some() {
            flags |= FLAG_POSTERIOR;
        }
        let orders = stage1
            .arx
            .map_or([0; 3], |arx| [arx.na(), arx.nb(), arx.delay()]);
        let (kind, experts) = match &e.regressor {
            FittedRegressor::Piecewise(p) => (REGRESSOR_PIECEWISE, p.experts().len()),
            _ => (REGRESSOR_NETWORK, 0),
        };
        if experts > MAX_EXPERTS {
            return Err(refuse(format!(
                "{experts} experts, the runtime takes at most {MAX_EXPERTS}"
            )));
        }
        let shape = &e.shape;
        for v in [
            e.param_names.len(),
            shape.n_inputs,
            shape.n_outputs,
            shape.n_samples,
            orders[0],
            orders[1],
            orders[2],
            flags as usize,
            kind as usize,
            experts,
            0,
            0,
        ] {
            self.u32(v)?;
        }
        debug_assert_eq!(self.bytes.len(), HEADER_BYTES);
        Ok(())
    }

    /// The parameters' transforms and box, stage 2, then the optional
    /// parts in the header's order.
    fn parts(&mut self, e: &Estimator, stage1: &RuntimeStage1<'_>) -> Result<()> {
        let transforms: Vec<usize> = e
            .marginals
            .iter()
            .map(|m| match m.transform() {
                Transform::Identity => TRANSFORM_IDENTITY as usize,
                Transform::Log => TRANSFORM_LOG as usize,
            })
            .collect();
        self.u32s(&transforms)?;
        self.f64s(&e.lower);
        self.f64s(&e.upper);
        if let Some(network) = stage1.learned {
            self.learned(network)?;
        }
        if let Some(car) = stage1.linearized {
            self.f64s(&car.to_words());
        }
        match &e.regressor {
            FittedRegressor::Linear(linear) => self.linear(linear)?,
            FittedRegressor::Mlp(mlp) => self.mlp(mlp)?,
            FittedRegressor::Piecewise(piecewise) => {
                let (start, width) = piecewise.pieces_start_width();
                self.f64s(&[start, width]);
                self.mlp(piecewise.global())?;
                for expert in piecewise.experts() {
                    self.mlp(expert)?;
                }
            }
        }
        if let Some(intervals) = &e.intervals {
            self.f64s(intervals.half_widths());
        }
        if let Some(adaptive) = &e.adaptive {
            let (floor, quantile, difficulty) = adaptive.parts();
            self.f64s(floor);
            self.f64s(quantile);
            self.mlp(difficulty)?;
        }
        if let Some(envelope) = &e.envelope {
            let (mean, factor) = envelope.parts();
            self.f64s(&[envelope.threshold()]);
            self.f64s(mean);
            self.f64s(factor);
        }
        if let Some(transformed) = stage1.transformed {
            self.output_transforms(transformed, e.shape.n_outputs)?;
        }
        if let Some(family) = e.runtime_family() {
            self.f64s(&[family.sample_time()]);
            for j in 0..family.n_inputs() {
                if let Some(ranges) = family.ranges(j) {
                    self.f64s(ranges.as_flattened());
                }
            }
        }
        if let Some(posterior) = &e.posterior {
            self.posterior(posterior)?;
        }
        Ok(())
    }

    /// The posterior's shape, supports, standardization, spread and
    /// network; the network's targets are its head as it is (mean 0,
    /// scale 1), so the runtime's standardization changes no bit of it.
    fn posterior(&mut self, posterior: &FittedMixture) -> Result<()> {
        let shape = posterior.shape();
        if shape.components > MAX_COMPONENTS {
            return Err(refuse(format!(
                "a posterior of {} components, the runtime takes at most {MAX_COMPONENTS}; \
                 train with --posterior {MAX_COMPONENTS} or fewer",
                shape.components
            )));
        }
        // The section's length in bytes (third count, set below) lets a
        // runtime built without draws step over it.
        let start = self.bytes.len();
        self.u32s(&[shape.components, shape.dim, 0])?;
        let (codes, bounds): (Vec<usize>, Vec<[f64; 2]>) = posterior
            .supports()
            .iter()
            .map(|support| match *support {
                Support::Real => (SUPPORT_REAL as usize, [0.0, 0.0]),
                Support::Positive => (SUPPORT_POSITIVE as usize, [0.0, 0.0]),
                Support::Interval { low, high } => (SUPPORT_INTERVAL as usize, [low, high]),
            })
            .unzip();
        self.u32s(&codes)?;
        self.f64s(bounds.as_flattened());
        let unbounded = posterior.unbounded_scaling();
        self.f64s(unbounded.mean());
        self.f64s(unbounded.scale());
        // The logarithm is the host's (`FittedMixture`'s), written so that
        // the runtime widens the head by the same bits.
        self.f64s(&[posterior.spread(), posterior.spread().ln()]);
        let (sizes, params) = posterior.network();
        let head = sizes.last().copied().unwrap_or(0);
        let targets = Standardizer::identity(head);
        self.network(
            sizes,
            posterior.feature_scaling(),
            &targets,
            &[params.to_vec()],
        )?;
        let length = self.bytes.len() - start;
        let length = u32::try_from(length)
            .map_err(|_| refuse(format!("a posterior of {length} bytes exceeds 32 bits")))?;
        self.bytes[start + 8..start + 12].copy_from_slice(&length.to_le_bytes());
        Ok(())
    }
}
