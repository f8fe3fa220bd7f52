//! An exported estimator, checked once and then read in place.

use twostage_kernels::Values;

use crate::bytes::{Cursor, LeF64s, u32_at};
use crate::error::Error;
use crate::format::{
    CHECKSUM_FROM, FLAG_ADAPTIVE, FLAG_CONFORMAL, FLAG_ENVELOPE, FLAG_INPUT_FAMILY,
    FLAG_LEARNED_SUMMARY, FLAG_LINEARIZED, FLAG_OUTPUT_TRANSFORMS, FLAG_POSTERIOR,
    FLAG_SIGNAL_SUMMARY, HEADER_BYTES, MAGIC, MAX_EXPERTS, MAX_ORDER, MAX_PARAMETERS, MAX_SIGNALS,
    REGRESSOR_NETWORK, REGRESSOR_PIECEWISE, SIGNAL_IDENTITY, SIGNAL_LOG, SIGNAL_LOG1P,
    TRANSFORM_IDENTITY, TRANSFORM_LOG, VERSION, VERSION_WITHOUT_FAMILY, VERSION_WITHOUT_LEARNED,
    VERSION_WITHOUT_LINEARIZED, VERSION_WITHOUT_POSTERIOR, VERSION_WITHOUT_SUMMARY,
};
use crate::learned::Learned;
use crate::network::Network;
use crate::posterior::Posterior;
use twostage_kernels::linearized::{CarLinearization, LINEARIZED_FEATURES};

/// Stage 2: one network, or a global one routing to experts.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Regressor<'a> {
    Network(Network<'a>),
    Piecewise {
        global: Network<'a>,
        start: f64,
        width: f64,
        experts: [u32; MAX_EXPERTS],
        count: usize,
    },
}

/// Normalized split-conformal intervals.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Adaptive<'a> {
    pub(crate) floor: LeF64s<'a>,
    pub(crate) quantile: LeF64s<'a>,
    pub(crate) difficulty: Network<'a>,
}

/// Where the training features lie.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Envelope<'a> {
    pub(crate) threshold: f64,
    pub(crate) mean: LeF64s<'a>,
    pub(crate) factor: LeF64s<'a>,
}

/// A trained estimator exported by `twostage export --to runtime`, checked
/// once (magic, version, length, checksum, every count and value) and then
/// read where it lies: no copy, no allocation.
///
/// ```
/// # use twostage::{TwoStage, models::{Benchmark, Simulator, experiment_rng}};
/// # let model = Benchmark::builder().n_samples(200).build()?;
/// # let trained = TwoStage::builder(&model).simulations(300).validation(0)
/// #     .calibration(100).linear(1e-6)?.train()?;
/// # let blob: Vec<u8> = trained.to_runtime()?;
/// # let mut record = model.spec().new_record();
/// # model.simulate(&[0.4], &mut experiment_rng(1, 0), &mut record)?;
/// # let (inputs, outputs) = (record.input(0).to_vec(), record.output(0).to_vec());
/// use twostage_runtime::{Estimator, Stream};
/// let estimator = Estimator::from_bytes(&blob)?;
/// let mut work = vec![0.0; estimator.workspace_len()];
/// let mut stream = Stream::new(&estimator, &mut work)?;
/// for (u, y) in inputs.iter().zip(&outputs) {
///     stream.push(&[*u], &[*y])?; // as the samples arrive
/// }
/// let (mut theta, mut half_widths) = ([0.0], [0.0]);
/// let assessment = stream.finish(&mut theta, &mut half_widths)?;
/// let host = trained.estimate(&inputs, &outputs)?;
/// assert!((theta[0] - host[0]).abs() <= 1e-9 * host[0].abs());
/// // The flag is the host's too.
/// let on_host = trained.assess(&record)?;
/// assert_eq!(assessment.out_of_distribution(), on_host.out_of_distribution());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Estimator<'a> {
    pub(crate) q: usize,
    pub(crate) n_inputs: usize,
    pub(crate) n_outputs: usize,
    pub(crate) trained_samples: usize,
    pub(crate) na: usize,
    pub(crate) nb: usize,
    pub(crate) delay: usize,
    pub(crate) transforms: &'a [u8],
    pub(crate) lower: LeF64s<'a>,
    pub(crate) upper: LeF64s<'a>,
    pub(crate) regressor: Regressor<'a>,
    pub(crate) conformal: Option<LeF64s<'a>>,
    pub(crate) adaptive: Option<Adaptive<'a>>,
    pub(crate) envelope: Option<Envelope<'a>>,
    /// Where the output transforms' codes start in the blob (0: none);
    /// an offset rather than two slices keeps the view within the C
    /// API's opaque storage.
    output_transforms_at: usize,
    /// Where the input family starts in the blob (0: none).
    input_family_at: usize,
    /// Whether stage 1 appends each signal's summary.
    pub(crate) signal_summary: bool,
    /// Where the learned stage 1's network, or the linearized stage 1's
    /// car, starts in the blob (0: neither; the two never meet). One
    /// offset for both keeps the view within the C API's opaque storage.
    stage1_at: usize,
    /// Whether the section at `stage1_at` is the linearized car's.
    linearized: bool,
    /// Where the posterior's density starts in the blob (0: none); read
    /// again where it lies when drawn from, as an expert is; 32 bits, as
    /// the blob's length is, keep the view within the C API's storage.
    posterior_at: u32,
    blob: &'a [u8],
    max_width: usize,
}

impl<'a> Estimator<'a> {
    /// Check a blob and view it as an estimator.
    ///
    /// # Errors
    /// Any [`Error`] of the blob kind: bad magic, another version, a wrong
    /// length or checksum, a count beyond the runtime's limits
    /// ([`crate::format`]), a non-finite or out-of-range value.
    pub fn from_bytes(blob: &'a [u8]) -> Result<Self, Error> {
        if blob.get(..4) != Some(&MAGIC[..]) {
            return Err(Error::BadMagic);
        }
        let version = u32_at(blob, 4).ok_or(Error::Truncated { at: 4 })?;
        if !(VERSION_WITHOUT_FAMILY..=VERSION).contains(&version) {
            return Err(Error::UnsupportedVersion { found: version });
        }
        let declared = u32_at(blob, 8).ok_or(Error::Truncated { at: 8 })? as usize;
        if declared != blob.len() || declared < HEADER_BYTES {
            return Err(Error::Length {
                declared,
                actual: blob.len(),
            });
        }
        let stored = u32_at(blob, 12).ok_or(Error::Truncated { at: 12 })?;
        let actual = crate::format::checksum(blob.get(CHECKSUM_FROM..).unwrap_or(&[]));
        if stored != actual {
            return Err(Error::Checksum { stored, actual });
        }
        Self::read(blob, version)
    }

    fn read(blob: &'a [u8], version: u32) -> Result<Self, Error> {
        let mut c = Cursor::new(blob, CHECKSUM_FROM);
        let q = c.count("parameter count", MAX_PARAMETERS)?;
        let n_inputs = c.count("input count", MAX_SIGNALS)?;
        let n_outputs = c.count("output count", MAX_SIGNALS)?;
        let trained_samples = c.u32()? as usize;
        let na = c.count("na", MAX_ORDER)?;
        let nb = c.count("nb", MAX_ORDER)?;
        let delay = c.count("delay", MAX_ORDER)?;
        let flags_at = c.at;
        let flags = c.u32()?;
        let kind_at = c.at;
        let kind = c.u32()?;
        let n_experts = c.count("expert count", MAX_EXPERTS)?;
        let (r1, r2) = (c.u32()?, c.u32()?);
        let linearized = version >= VERSION_WITHOUT_POSTERIOR && flags & FLAG_LINEARIZED != 0;
        let mut known = FLAG_CONFORMAL | FLAG_ADAPTIVE | FLAG_ENVELOPE | FLAG_OUTPUT_TRANSFORMS;
        if version >= VERSION_WITHOUT_SUMMARY {
            known |= FLAG_INPUT_FAMILY;
        }
        if version >= VERSION_WITHOUT_LEARNED {
            known |= FLAG_SIGNAL_SUMMARY;
        }
        if version >= VERSION_WITHOUT_LINEARIZED {
            known |= FLAG_LEARNED_SUMMARY;
        }
        if version >= VERSION_WITHOUT_POSTERIOR {
            known |= FLAG_LINEARIZED;
        }
        if version >= VERSION {
            known |= FLAG_POSTERIOR;
        }
        // The network reads the outputs as measured, as the summary does:
        // neither goes with output transforms.
        let learned = flags & FLAG_LEARNED_SUMMARY != 0;
        let transformed = flags & FLAG_OUTPUT_TRANSFORMS != 0;
        let measured = flags & (FLAG_SIGNAL_SUMMARY | FLAG_LEARNED_SUMMARY) != 0;
        // The linearized stage 1 is the whole of stage 1: nothing before
        // or after it.
        let mixed = linearized && (measured || transformed);
        if flags & !known != 0 || r1 != 0 || r2 != 0 || (measured && transformed) || mixed {
            return Err(Error::Invalid {
                field: "flags",
                at: flags_at,
            });
        }
        // A linearized stage 1 reads the car's one input and output for
        // its two parameters, and no ARX coefficients.
        let shape_ok = if linearized {
            (q, n_inputs, n_outputs, na, nb, delay) == (2, 1, 1, 0, 0, 0)
        } else {
            q > 0 && n_outputs > 0 && na + nb > 0 && (nb == 0 || n_inputs > 0)
        };
        if !shape_ok {
            return Err(Error::Invalid {
                field: "record shape or ARX orders",
                at: CHECKSUM_FROM,
            });
        }
        let signal_summary = flags & FLAG_SIGNAL_SUMMARY != 0;
        let mut n_features = n_outputs * (na + n_inputs * nb)
            + if signal_summary {
                SUMMARY_LEN * (n_inputs + n_outputs)
            } else {
                0
            };
        let transforms_at = c.at;
        let transforms = c.u32s(q)?;
        if (0..q).any(|j| {
            !matches!(
                u32_at(transforms, 4 * j),
                Some(TRANSFORM_IDENTITY | TRANSFORM_LOG)
            )
        }) {
            return Err(Error::Invalid {
                field: "transform code",
                at: transforms_at,
            });
        }
        let bounds_at = c.at;
        let lower = c.finite("lower bound", q)?;
        let upper = c.finite("upper bound", q)?;
        if (0..q).any(|j| lower.at(j) >= upper.at(j)) {
            return Err(Error::Invalid {
                field: "prior box (lower >= upper)",
                at: bounds_at,
            });
        }
        // Before stage 2, whose networks read its features.
        if learned && !cfg!(feature = "learned") {
            return Err(Error::NotBuiltIn { feature: "learned" });
        }
        let learned_at = if learned {
            let at = c.at;
            n_features += Learned::read(&mut c, n_inputs + n_outputs)?.n_features();
            at
        } else {
            0
        };
        if linearized && !cfg!(feature = "linearized") {
            return Err(Error::NotBuiltIn {
                feature: "linearized",
            });
        }
        let linearized_at = if linearized {
            let at = c.at;
            let numbers = c.f64s(CarLinearization::WORDS)?;
            if linearization_at(numbers).is_none() {
                return Err(Error::Invalid {
                    field: "linearization",
                    at,
                });
            }
            n_features += LINEARIZED_FEATURES;
            at
        } else {
            0
        };
        let regressor = match kind {
            REGRESSOR_NETWORK if n_experts == 0 => {
                Regressor::Network(Network::read(&mut c, n_features, q)?)
            }
            REGRESSOR_PIECEWISE if n_experts > 0 => {
                let start = c.f64("piece start")?;
                let width_at = c.at;
                let width = c.f64("piece width")?;
                if width <= 0.0 {
                    return Err(Error::Invalid {
                        field: "piece width",
                        at: width_at,
                    });
                }
                let global = Network::read(&mut c, n_features, q)?;
                let mut experts = [0u32; MAX_EXPERTS];
                for slot in experts.iter_mut().take(n_experts) {
                    *slot = u32::try_from(c.at).map_err(|_| Error::Truncated { at: c.at })?;
                    Network::read(&mut c, n_features, q)?;
                }
                Regressor::Piecewise {
                    global,
                    start,
                    width,
                    experts,
                    count: n_experts,
                }
            }
            _ => {
                return Err(Error::Invalid {
                    field: "regressor kind",
                    at: kind_at,
                });
            }
        };
        let conformal = if flags & FLAG_CONFORMAL != 0 {
            let at = c.at;
            let widths = c.f64s(q)?;
            if (0..q).any(|j| widths.at(j).is_nan() || widths.at(j) < 0.0) {
                return Err(Error::Invalid {
                    field: "conformal half-width",
                    at,
                });
            }
            Some(widths)
        } else {
            None
        };
        let adaptive = if flags & FLAG_ADAPTIVE != 0 {
            let at = c.at;
            let floor = c.finite("adaptive floor", q)?;
            let quantile = c.f64s(q)?;
            let bad = (0..q)
                .any(|j| floor.at(j) <= 0.0 || quantile.at(j).is_nan() || quantile.at(j) < 0.0);
            if bad {
                return Err(Error::Invalid {
                    field: "adaptive floor or quantile",
                    at,
                });
            }
            let difficulty = Network::read(&mut c, n_features, q)?;
            Some(Adaptive {
                floor,
                quantile,
                difficulty,
            })
        } else {
            None
        };
        let envelope = if flags & FLAG_ENVELOPE != 0 {
            let at = c.at;
            let threshold = c.f64("envelope threshold")?;
            let mean = c.finite("envelope mean", n_features)?;
            let factor_at = c.at;
            let factor = c.finite("envelope factor", n_features * n_features)?;
            if threshold < 0.0 {
                return Err(Error::Invalid {
                    field: "envelope threshold",
                    at,
                });
            }
            if (0..n_features).any(|j| factor.at(j * n_features + j) <= 0.0) {
                return Err(Error::Invalid {
                    field: "envelope factor diagonal",
                    at: factor_at,
                });
            }
            Some(Envelope {
                threshold,
                mean,
                factor,
            })
        } else {
            None
        };
        let output_transforms_at = if flags & FLAG_OUTPUT_TRANSFORMS != 0 {
            read_output_transforms(&mut c, n_outputs)?
        } else {
            0
        };
        let input_family_at = if flags & FLAG_INPUT_FAMILY != 0 {
            read_input_family(&mut c, n_inputs)?
        } else {
            0
        };
        let posterior_at = if flags & FLAG_POSTERIOR != 0 {
            let at = c.at;
            if cfg!(feature = "posterior") {
                Posterior::read(&mut c, n_features, q)?;
            } else {
                Posterior::skip(&mut c)?;
            }
            u32::try_from(at).map_err(|_| Error::Truncated { at })?
        } else {
            0
        };
        if c.at != blob.len() {
            return Err(Error::TrailingBytes { at: c.at });
        }
        let mut estimator = Self {
            q,
            n_inputs,
            n_outputs,
            trained_samples,
            na,
            nb,
            delay,
            transforms,
            lower,
            upper,
            regressor,
            conformal,
            adaptive,
            envelope,
            output_transforms_at,
            input_family_at,
            signal_summary,
            stage1_at: learned_at.max(linearized_at),
            linearized,
            posterior_at,
            blob,
            max_width: 0,
        };
        estimator.max_width = estimator.networks_max_width();
        Ok(estimator)
    }

    fn networks_max_width(&self) -> usize {
        let mut width = self.adaptive.map_or(0, |a| a.difficulty.max_width());
        if let Some(posterior) = self.posterior() {
            width = width.max(posterior.network.max_width());
        }
        match self.regressor {
            Regressor::Network(n) => width = width.max(n.max_width()),
            Regressor::Piecewise { global, count, .. } => {
                width = width.max(global.max_width());
                for k in 0..count {
                    width = width.max(self.expert(k).map_or(0, |e| e.max_width()));
                }
            }
        }
        width
    }

    /// The posterior's density (read again where it lies), where the
    /// blob carries one and this build reads it (the feature `posterior`).
    pub(crate) fn posterior(&self) -> Option<Posterior<'a>> {
        if self.posterior_at == 0 || !cfg!(feature = "posterior") {
            return None;
        }
        Posterior::read(
            &mut Cursor::new(self.blob, self.posterior_at as usize),
            self.n_features(),
            self.q,
        )
        .ok()
    }

    /// Words of workspace a draw needs beside the network's scratch (the
    /// head and one draw's normals), from the section's counts, checked
    /// when the blob was read: 0 without a posterior or the feature.
    pub(crate) fn posterior_words(&self) -> usize {
        if self.posterior_at == 0 || !cfg!(feature = "posterior") {
            return 0;
        }
        let at = self.posterior_at as usize;
        let count = |offset: usize| u32_at(self.blob, at + offset).map_or(0, |v| v as usize);
        let shape = twostage_kernels::mixture::MixtureShape {
            components: count(0),
            dim: count(4),
        };
        shape.outputs() + shape.dim
    }

    /// Whether the blob carries the posterior's density, so that
    /// [`crate::Stream::finish_with_draws`] draws the parameters given a
    /// record (in a build with the feature `posterior`; one without it
    /// estimates from the blob as from one without a posterior).
    pub fn has_posterior(&self) -> bool {
        self.posterior_at != 0
    }

    /// Expert `k` of a piecewise regressor (read again where it lies).
    pub(crate) fn expert(&self, k: usize) -> Option<Network<'a>> {
        let Regressor::Piecewise { experts, count, .. } = self.regressor else {
            return None;
        };
        if k >= count {
            return None;
        }
        let at = *experts.get(k)? as usize;
        Network::read(&mut Cursor::new(self.blob, at), self.n_features(), self.q).ok()
    }

    /// Number of parameters q.
    pub fn n_parameters(&self) -> usize {
        self.q
    }
    /// Input signals per sample.
    pub fn n_inputs(&self) -> usize {
        self.n_inputs
    }
    /// Output signals per sample.
    pub fn n_outputs(&self) -> usize {
        self.n_outputs
    }
    /// The record length the estimator was trained on: other lengths are
    /// estimated too, but the validation speaks for this one.
    pub fn trained_samples(&self) -> usize {
        self.trained_samples
    }
    /// Stage 1's features: `n_outputs * (na + n_inputs * nb)` ARX
    /// coefficients, then four summary numbers per signal where stage 1
    /// appends them, then two per channel of the learned network's last
    /// layer where it learns; a linearized stage 1's eight alone.
    pub fn n_features(&self) -> usize {
        self.arx_features()
            + if self.signal_summary {
                SUMMARY_LEN * (self.n_inputs + self.n_outputs)
            } else {
                0
            }
            + self.learned().map_or(0, |l| l.n_features())
            + if self.has_linearized_stage1() {
                LINEARIZED_FEATURES
            } else {
                0
            }
    }

    /// The learned stage 1's network, checked at load.
    pub(crate) fn learned(&self) -> Option<Learned<'a>> {
        // Without the feature no blob with a network loads, and the
        // constant lets the linker drop the network's code.
        if !cfg!(feature = "learned") {
            return None;
        }
        match self.stage1_at {
            _ if self.linearized => None,
            0 => None,
            at => Learned::parse(
                &mut Cursor::new(self.blob, at),
                self.n_inputs + self.n_outputs,
            )
            .ok(),
        }
    }

    /// The linearized stage 1's car and linearization, checked at load.
    pub(crate) fn linearization(&self) -> Option<CarLinearization> {
        // Without the feature no such blob loads, and the constant lets
        // the linker drop the car's code.
        if !cfg!(feature = "linearized") || !self.has_linearized_stage1() {
            return None;
        }
        let numbers = Cursor::new(self.blob, self.stage1_at)
            .f64s(CarLinearization::WORDS)
            .ok()?;
        linearization_at(numbers)
    }

    /// Whether stage 1 linearizes the car (the host's `linearized`): its
    /// features are what the record says of the parameters, by the
    /// model's own sensitivities.
    pub fn has_linearized_stage1(&self) -> bool {
        self.linearized && self.stage1_at != 0
    }

    /// Whether stage 1 appends a learned summary of the record (a
    /// convolutional network's time averages, `+learned` on the host).
    pub fn has_learned_summary(&self) -> bool {
        !self.linearized && self.stage1_at != 0
    }

    /// The fewest samples a record (or a window) must hold: one
    /// regression for each output, and one position of the learned
    /// network's last layer.
    pub fn min_samples(&self) -> usize {
        if self.has_linearized_stage1() {
            // The host's least for a record of the car: two samples.
            return 2;
        }
        let regression = self.first_sample() + self.per_output();
        regression.max(self.learned().map_or(0, |l| l.min_samples()))
    }
    /// Whether stage 1 appends each input's and output's mean, RMS, peak
    /// and mean frequency to the ARX coefficients.
    pub fn has_signal_summary(&self) -> bool {
        self.signal_summary
    }
    /// The ARX coefficients among the features.
    pub(crate) fn arx_features(&self) -> usize {
        self.n_outputs * self.per_output()
    }
    /// Lower bound of parameter `j`'s prior box (NaN past the end).
    pub fn lower(&self, j: usize) -> f64 {
        self.lower.at(j)
    }
    /// Upper bound of parameter `j`'s prior box (NaN past the end).
    pub fn upper(&self, j: usize) -> f64 {
        self.upper.at(j)
    }
    /// The interval `theta +- half_widths` kept inside the prior's box,
    /// into `low` and `high`, exactly as the host's `interval_in_box`
    /// (one routine, in the kernels): a parameter's interval never leaves
    /// its prior's support; a NaN half-width gives NaN bounds.
    ///
    /// # Errors
    /// [`Error::OutputTooShort`] when a slice holds fewer than q numbers.
    pub fn interval(
        &self,
        theta: &[f64],
        half_widths: &[f64],
        low: &mut [f64],
        high: &mut [f64],
    ) -> Result<(), Error> {
        let q = self.n_parameters();
        if [theta.len(), half_widths.len(), low.len(), high.len()]
            .iter()
            .any(|&len| len < q)
        {
            return Err(Error::OutputTooShort { needed: q });
        }
        twostage_kernels::vector::interval_in_box(
            theta,
            half_widths,
            &self.lower,
            &self.upper,
            low,
            high,
        );
        Ok(())
    }
    /// Whether the estimator has intervals (adaptive or conformal).
    pub fn has_intervals(&self) -> bool {
        self.adaptive.is_some() || self.conformal.is_some()
    }
    /// Whether it can tell records unlike its training ones.
    pub fn has_envelope(&self) -> bool {
        self.envelope.is_some()
    }

    /// Regressor columns per output: na output lags and nb lags of each
    /// input.
    pub(crate) fn per_output(&self) -> usize {
        self.na + self.n_inputs * self.nb
    }
    /// The first sample whose regressors are all inside the record.
    pub(crate) fn first_sample(&self) -> usize {
        twostage_kernels::lagged::arx_first_sample(self.na, self.nb, self.delay)
    }
    pub(crate) fn max_width(&self) -> usize {
        self.max_width
    }
    pub(crate) fn is_log(&self, j: usize) -> bool {
        u32_at(self.transforms, 4 * j) == Some(TRANSFORM_LOG)
    }

    /// Whether it judges each record's input against the family of inputs
    /// its training records spanned ([`crate::Assessment::input_outside_family`]).
    pub fn has_input_family(&self) -> bool {
        self.input_family_at != 0
    }

    /// The range `[low, high]` the training records spanned of input
    /// `j`'s summary number `k` (0 mean, 1 RMS, 2 peak, 3 mean frequency
    /// in Hz, as `twostage_kernels::input_summary::SUMMARY_NAMES`), before
    /// the margin a record may lie beyond it; `None` without a family or
    /// past the ends.
    pub fn input_family_range(&self, j: usize, k: usize) -> Option<[f64; 2]> {
        if !self.has_input_family() || j >= self.n_inputs || k >= SUMMARY_LEN {
            return None;
        }
        let at = 1 + 2 * (SUMMARY_LEN * j + k);
        Some([self.family().at(at), self.family().at(at + 1)])
    }

    /// Input `j`'s four ranges, as [`Estimator::input_family_range`] gives
    /// them one by one, for an estimator with a family and `j` an input.
    pub(crate) fn input_family_ranges(&self, j: usize) -> [[f64; 2]; SUMMARY_LEN] {
        let family = self.family();
        core::array::from_fn(|k| {
            let at = 1 + 2 * (SUMMARY_LEN * j + k);
            [family.at(at), family.at(at + 1)]
        })
    }

    /// The sample time the family's frequencies are in (NaN without a
    /// family).
    pub(crate) fn input_sample_time(&self) -> f64 {
        self.family().at(0)
    }

    /// The input family's numbers, checked at load (empty without one).
    fn family(&self) -> LeF64s<'a> {
        let bytes = match self.input_family_at {
            0 => &[],
            at => self.blob.get(at..).unwrap_or_default(),
        };
        LeF64s { bytes }
    }

    /// Whether an estimate transforms the output samples (logarithms)
    /// before stage 1: a sample outside a transform's domain is then
    /// replaced by the smallest value training showed, and counted in
    /// [`crate::Assessment::untransformed_samples`].
    pub fn transforms_outputs(&self) -> bool {
        self.output_transforms_at != 0
    }

    /// Output `j`'s sample as stage 1 takes it: transformed, and
    /// `Err(transformed floor)` for a sample outside the domain.
    pub(crate) fn output_sample(&self, j: usize, value: f64) -> Result<f64, f64> {
        if self.output_transforms_at == 0 {
            return Ok(value);
        }
        let code = u32_at(self.blob, self.output_transforms_at + 4 * j);
        let floors_at = floors_offset(self.output_transforms_at, self.n_outputs);
        let floor = Cursor::new(self.blob, floors_at + 8 * j)
            .f64("floor")
            .unwrap_or(f64::NAN);
        match code {
            Some(SIGNAL_LOG) if value > 0.0 => Ok(libm::log(value)),
            Some(SIGNAL_LOG) => Err(libm::log(floor)),
            Some(SIGNAL_LOG1P) if value > -1.0 => Ok(libm::log1p(value)),
            Some(SIGNAL_LOG1P) => Err(libm::log1p(floor)),
            _ => Ok(value),
        }
    }
}

/// The linearization `numbers` hold, `None` for one that is not
/// (`CarLinearization::fault`).
fn linearization_at(numbers: LeF64s<'_>) -> Option<CarLinearization> {
    let words: [f64; CarLinearization::WORDS] = core::array::from_fn(|j| numbers.at(j));
    CarLinearization::from_words(&words).ok()
}

/// Numbers in one input's summary.
pub(crate) const SUMMARY_LEN: usize = twostage_kernels::input_summary::SUMMARY_NAMES.len();

/// The input family: a positive sample time, then per input each summary
/// number's finite `[low, high]` with `low <= high`; its offset.
fn read_input_family(c: &mut Cursor<'_>, n_inputs: usize) -> Result<usize, Error> {
    let at = c.at;
    let sample_time = c.f64("input family sample time")?;
    let ranges = c.finite("input family range", 2 * SUMMARY_LEN * n_inputs)?;
    let ordered = (0..SUMMARY_LEN * n_inputs).all(|k| ranges.at(2 * k) <= ranges.at(2 * k + 1));
    if sample_time <= 0.0 || n_inputs == 0 || !ordered {
        return Err(Error::Invalid {
            field: "input family",
            at,
        });
    }
    Ok(at)
}

/// Where the floors follow `n_outputs` codes starting at `codes_at` (the
/// codes are padded to 8 bytes).
fn floors_offset(codes_at: usize, n_outputs: usize) -> usize {
    (codes_at + 4 * n_outputs).div_ceil(8) * 8
}

/// The output transforms' codes and floors (each floor inside its
/// transform's domain); their offset.
fn read_output_transforms(c: &mut Cursor<'_>, n_outputs: usize) -> Result<usize, Error> {
    let at = c.at;
    let codes = c.u32s(n_outputs)?;
    let floors_at = c.at;
    let floors = c.finite("output transform floor", n_outputs)?;
    debug_assert_eq!(floors_at, floors_offset(at, n_outputs));
    for j in 0..n_outputs {
        let floor = floors.at(j);
        let valid = match u32_at(codes, 4 * j) {
            Some(SIGNAL_IDENTITY) => true,
            Some(SIGNAL_LOG) => floor > 0.0,
            Some(SIGNAL_LOG1P) => floor > -1.0,
            _ => false,
        };
        if !valid {
            return Err(Error::Invalid {
                field: "output transform code or floor",
                at,
            });
        }
    }
    Ok(at)
}
