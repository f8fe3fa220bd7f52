//! Stage 1 accumulated sample by sample, then the rest of the estimate.

use twostage_kernels::Values;
use twostage_kernels::cholesky::solve_lower_in_place;
use twostage_kernels::input_summary::{ACCUMULATOR_WORDS, InputAccumulator, outside_family};
use twostage_kernels::linearized::{CarStream, LinearizedSums, WindowBlocks};
use twostage_kernels::vector::clip_to_box;

use crate::correlations::{Memory, Past, Shape, packed, solve, store};
use crate::error::Error;
use crate::estimator::{Estimator, Regressor, SUMMARY_LEN};
use crate::format::MAX_SIGNALS;

/// Words at the start of the workspace: samples pushed, the state, the
/// sample that was not finite (for a failed stream), the output samples
/// an output transform could not take (of the window, for a window), and
/// the window's length (0: the whole record).
pub(crate) const STATUS_WORDS: usize = 5;
const OPEN: f64 = 0.0;
const FAILED: f64 = 2.0;

/// Where each part of a stream's workspace lies (in `f64`), after the
/// status words.
pub(crate) struct Layout {
    pub(crate) shape: Shape,
    /// The window's length, 0 for a whole record.
    window: usize,
    /// A record's last L samples (three words each) and first L, or a
    /// window's ring of samples.
    history: usize,
    first: usize,
    /// A window's count of untransformed outputs per sample (of an
    /// estimator that transforms its outputs).
    marks: usize,
    sums: usize,
    /// One accumulator per input, for a record's stream of an estimator
    /// with a family, and one per output after them where stage 1 appends
    /// the signals' summary (a window summarizes its ring at finish).
    family: usize,
    /// The learned network's state: fed by each push of a record's
    /// stream, by the window's samples at a window's finish.
    learned: usize,
    /// The linearized stage 1's car run since the stream's first sample
    /// and its sums (a window's current block's), then a window's ring of
    /// whole blocks' sums.
    linearized: usize,
    features: usize,
    scratch: usize,
    /// The posterior's head and one draw's normal numbers (an estimator
    /// with a posterior), last: only a finish that draws cuts them off.
    pub(crate) posterior: usize,
    pub(crate) total: usize,
}

impl Layout {
    /// The workspace of a stream over whole records (`window` 0) or over
    /// a sliding window of `window` samples.
    pub(crate) fn of(e: &Estimator<'_>, window: usize) -> Self {
        let n = e.per_output();
        let shape = Shape {
            outputs: e.n_outputs,
            signals: e.n_outputs + e.n_inputs,
            lags: e.first_sample(),
        };
        let features = e.n_features();
        // One output's normal equations (packed, double-double) while it
        // is solved, or the network's input and layers, or the envelope's
        // whitened features.
        let scratch = (n * (n + 1) + 2 * n).max(features + 2 * e.max_width());
        let linear = e.has_linearized_stage1();
        // A linearized stage 1 keeps no lagged products; a window of it
        // keeps its samples only to summarize its input at finish.
        let sums = if linear { 0 } else { shape.sum_words() };
        let (history, first, marks, family) = if window == 0 {
            let family = if e.has_signal_summary() {
                ACCUMULATOR_WORDS * (e.n_inputs + e.n_outputs)
            } else if e.has_input_family() {
                ACCUMULATOR_WORDS * e.n_inputs
            } else {
                0
            };
            (shape.history_words(), shape.first_words(), 0, family)
        } else {
            let marks = if e.transforms_outputs() { window } else { 0 };
            let ring = if linear && !e.has_input_family() {
                0
            } else {
                shape.signals.saturating_mul(window)
            };
            (ring, 0, marks, 0)
        };
        let learned = e.learned().map_or(0, |l| l.state_words());
        let linearized = if linear {
            CarStream::WORDS + LinearizedSums::WORDS * WindowBlocks::of(window).count
        } else {
            0
        };
        // From the section's counts: a push must not read the network.
        let posterior = e.posterior_words();
        let total = [
            history, first, marks, sums, family, learned, linearized, features, scratch, posterior,
        ]
        .iter()
        .fold(STATUS_WORDS, |total, words| total.saturating_add(*words));
        Self {
            shape,
            window,
            history,
            first,
            marks,
            sums,
            family,
            learned,
            linearized,
            features,
            scratch,
            posterior,
            total,
        }
    }

    /// The stream's memory, the window's marks, the input accumulators,
    /// the features and the scratch.
    pub(crate) fn split<'w>(&self, work: &'w mut [f64]) -> Parts<'w> {
        let (history, rest) = work.split_at_mut(self.history.min(work.len()));
        let (first, rest) = rest.split_at_mut(self.first.min(rest.len()));
        let (marks, rest) = rest.split_at_mut(self.marks.min(rest.len()));
        let (sums, rest) = rest.split_at_mut(self.sums.min(rest.len()));
        let (family, rest) = rest.split_at_mut(self.family.min(rest.len()));
        let (learned, rest) = rest.split_at_mut(self.learned.min(rest.len()));
        let (linearized, rest) = rest.split_at_mut(self.linearized.min(rest.len()));
        let (features, rest) = rest.split_at_mut(self.features.min(rest.len()));
        let scratch = rest.get_mut(..self.scratch).unwrap_or_default();
        let past = if self.window == 0 {
            Past::Record {
                first,
                last: history,
            }
        } else {
            Past::Window {
                ring: history,
                length: self.window,
            }
        };
        Parts {
            memory: Memory { past, sums },
            marks,
            family,
            learned,
            linearized,
            features,
            scratch,
        }
    }
}

/// A workspace cut into its parts.
pub(crate) struct Parts<'w> {
    memory: Memory<'w>,
    marks: &'w mut [f64],
    family: &'w mut [f64],
    learned: &'w mut [f64],
    linearized: &'w mut [f64],
    pub(crate) features: &'w mut [f64],
    pub(crate) scratch: &'w mut [f64],
}

/// An accumulator kept in a workspace's words.
fn accumulator(words: &[f64]) -> InputAccumulator {
    InputAccumulator::from_words(first_words(words))
}

/// Each input's summary judged against the estimator's family: bit
/// `4 j + k` set when input j's summary number k lies outside.
fn input_outside_family(e: &Estimator<'_>, summary_of: impl Fn(usize) -> InputAccumulator) -> u64 {
    let mut outside = 0u64;
    if !e.has_input_family() {
        return outside;
    }
    let sample_time = e.input_sample_time();
    for j in 0..e.n_inputs {
        let summary = summary_of(j).summary(sample_time);
        let ranges = e.input_family_ranges(j);
        for (k, out) in outside_family(summary, ranges).into_iter().enumerate() {
            if out {
                outside |= 1 << (SUMMARY_LEN * j + k);
            }
        }
    }
    outside
}

/// What an estimate says of itself besides theta.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Assessment {
    /// Which intervals the half-widths are.
    pub intervals: Intervals,
    /// Mahalanobis distance of the record's features from the training
    /// features, when the estimator has an envelope.
    pub feature_distance: Option<f64>,
    /// The distance 99.9% of training features stay within.
    pub distance_threshold: Option<f64>,
    /// Output samples outside their transform's domain (a logarithm of a
    /// non-positive value), replaced by the smallest value training
    /// showed: 0 unless the estimator transforms its outputs.
    pub untransformed_samples: usize,
    /// Which numbers of the record's input summaries lie outside the
    /// family the training records spanned (the host's
    /// `Assessment::input_deviations`): bit `4 j + k` for input j's number
    /// k (0 mean, 1 RMS, 2 peak, 3 mean frequency); 0 for an input of
    /// the family and for an estimator without one.
    pub input_outside_family: u64,
}

impl Assessment {
    /// Whether the record lies outside what training saw, by its features
    /// or by its input: the estimate is an extrapolation and the
    /// intervals do not speak for it.
    pub fn out_of_distribution(&self) -> bool {
        self.features_outside() || self.input_outside_family != 0
    }

    /// Whether the record's features lie beyond the envelope's threshold.
    pub fn features_outside(&self) -> bool {
        matches!((self.feature_distance, self.distance_threshold), (Some(d), Some(t)) if d > t)
    }
}

/// The intervals written into the half-widths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Intervals {
    /// None: the estimator was not calibrated (or no room was given).
    None,
    /// The same conformal half-widths for every record.
    Conformal,
    /// Half-widths that follow this record's difficulty.
    Adaptive,
}

/// One estimation in progress: push the samples as they arrive, then
/// [`Stream::finish`]. It keeps the normal equations (O(n^2) numbers) and
/// the last few samples, never the record, in the caller's workspace,
/// which holds all of its state: a stream can be dropped and
/// [`Stream::resume`]d over the same workspace (the C API does so on
/// every call). A [`Stream::window`] estimates the last N samples
/// instead, as a control unit re-estimates while the plant runs.
#[derive(Debug)]
pub struct Stream<'e, 'a, 'w> {
    pub(crate) estimator: &'e Estimator<'a>,
    pub(crate) window: usize,
    status: &'w mut [f64],
    pub(crate) work: &'w mut [f64],
}

impl<'e, 'a, 'w> Stream<'e, 'a, 'w> {
    /// A stream of whole records over `work`, which must hold
    /// [`Estimator::workspace_len`] numbers (a longer one is fine).
    ///
    /// # Errors
    /// [`Error::WorkspaceTooSmall`].
    pub fn new(estimator: &'e Estimator<'a>, work: &'w mut [f64]) -> Result<Self, Error> {
        let mut stream = Self::attach(estimator, 0, work)?;
        stream.reset();
        Ok(stream)
    }

    /// A stream over a window that slides: [`Stream::finish`] estimates
    /// the last `window` samples (all of them while fewer were pushed),
    /// the same numbers as a stream of those samples alone, to rounding.
    /// A linearized stage 1 is the exception: its car runs from the
    /// stream's first sample (where the plant was when the window began,
    /// not at rest), and its window gains and loses blocks of a tenth of
    /// its length, so a finish sums the current block and the whole
    /// blocks before it that fit (the whole window when it comes at a
    /// block's end).
    /// The stage-1 sums gain each sample as it is pushed and lose the one
    /// leaving the window, so a push costs about two and a half times a
    /// record stream's and a finish as much as a record's (plus a pass
    /// over the window's inputs, for an estimator with an input family). `work` holds
    /// [`Estimator::window_workspace_len`] numbers: the window's samples
    /// and the sums.
    ///
    /// ```
    /// # use twostage::{TwoStage, models::{Benchmark, Simulator, experiment_rng}};
    /// # let model = Benchmark::builder().n_samples(200).build()?;
    /// # let trained = TwoStage::builder(&model).simulations(300).validation(0)
    /// #     .calibration(100).linear(1e-6)?.train()?;
    /// # let blob = trained.to_runtime()?;
    /// # let mut record = model.spec().new_record();
    /// # model.simulate(&[0.4], &mut experiment_rng(1, 0), &mut record)?;
    /// # let (u, y) = (record.input(0).to_vec(), record.output(0).to_vec());
    /// use twostage_runtime::{Estimator, Stream};
    /// let estimator = Estimator::from_bytes(&blob)?;
    /// let mut work = vec![0.0; estimator.window_workspace_len(100)];
    /// let mut window = Stream::window(&estimator, 100, &mut work)?;
    /// let mut theta = [0.0];
    /// for t in 0..u.len() {
    ///     window.push(&[u[t]], &[y[t]])?;
    ///     if t + 1 >= 100 && (t + 1) % 50 == 0 {
    ///         window.finish(&mut theta, &mut [])?; // the last 100 samples
    ///     }
    /// }
    /// // The last window, estimated alone.
    /// let mut alone = [0.0];
    /// let mut work = vec![0.0; estimator.workspace_len()];
    /// estimator.estimate_record(&u[100..], &y[100..], &mut work, &mut alone, &mut [])?;
    /// assert!((theta[0] - alone[0]).abs() <= 1e-9 * alone[0].abs().max(1e-3));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::WindowTooShort`] for a window shorter than one regression
    /// (the ARX's first sample plus its regressors) or than the learned
    /// network's shortest record ([`Estimator::min_samples`]), and
    /// [`Error::WorkspaceTooSmall`].
    pub fn window(
        estimator: &'e Estimator<'a>,
        window: usize,
        work: &'w mut [f64],
    ) -> Result<Self, Error> {
        let needed = estimator.min_samples();
        if window < needed.max(1) {
            return Err(Error::WindowTooShort { window, needed });
        }
        let mut stream = Self::attach(estimator, window, work)?;
        stream.reset();
        Ok(stream)
    }

    /// The stream whose state `work` holds (from [`Stream::new`] or
    /// [`Stream::window`] over the same estimator), to go on pushing or
    /// to finish it.
    ///
    /// # Errors
    /// [`Error::WorkspaceTooSmall`], and [`Error::NotStarted`] for a
    /// workspace no stream was started in.
    pub fn resume(estimator: &'e Estimator<'a>, work: &'w mut [f64]) -> Result<Self, Error> {
        let whole = |v: f64| (0.0..4.0e15).contains(&v) && libm::trunc(v).to_bits() == v.to_bits();
        let word = |k: usize| work.get(k).copied().unwrap_or(f64::NAN);
        let (samples, state, window) = (word(0), word(1), word(4));
        let needed = estimator.min_samples();
        let window_ok = whole(window) && (window == 0.0 || window >= needed as f64);
        if !(whole(samples) && window_ok && [OPEN, FAILED].contains(&state)) {
            return Err(Error::NotStarted);
        }
        Self::attach(estimator, window as usize, work)
    }

    fn attach(
        estimator: &'e Estimator<'a>,
        window: usize,
        work: &'w mut [f64],
    ) -> Result<Self, Error> {
        let needed = Layout::of(estimator, window).total;
        if work.len() < needed {
            return Err(Error::WorkspaceTooSmall {
                needed,
                given: work.len(),
            });
        }
        let (status, work) = work.split_at_mut(STATUS_WORDS);
        Ok(Self {
            estimator,
            window,
            status,
            work,
        })
    }

    /// Forget every sample: ready for the next record (a window stays as
    /// long).
    pub fn reset(&mut self) {
        self.status.fill(0.0);
        if let Some(word) = self.status.get_mut(4) {
            *word = self.window as f64;
        }
        self.work.fill(0.0);
    }

    /// The window's length, or `None` for a stream of whole records.
    pub fn window_len(&self) -> Option<usize> {
        (self.window > 0).then_some(self.window)
    }

    /// Samples pushed so far.
    pub fn samples(&self) -> usize {
        self.status.first().map_or(0, |s| *s as usize)
    }

    fn set_samples(&mut self, samples: usize) {
        if let Some(s) = self.status.first_mut() {
            *s = samples as f64;
        }
    }

    /// The error a stream that cannot go on answers with.
    fn check_open(&self) -> Result<(), Error> {
        match self.status.get(1).copied() {
            Some(OPEN) => Ok(()),
            _ => Err(Error::NotFinite {
                sample: self.status.get(2).map_or(0, |s| *s as usize),
            }),
        }
    }

    fn set_state(&mut self, state: f64, sample: usize) {
        if let Some(s) = self.status.get_mut(1..3) {
            s.copy_from_slice(&[state, sample as f64]);
        }
    }

    /// Take the next sample: `inputs` and `outputs` at this sampling time.
    ///
    /// # Errors
    /// [`Error::SignalCount`] for slices of the wrong length (the sample is
    /// not taken); [`Error::NotFinite`] for a NaN or infinity, after which
    /// the record is refused as the host refuses it, until
    /// [`Stream::reset`].
    pub fn push(&mut self, inputs: &[f64], outputs: &[f64]) -> Result<(), Error> {
        let e = self.estimator;
        self.check_open()?;
        if inputs.len() != e.n_inputs || outputs.len() != e.n_outputs {
            return Err(Error::SignalCount {
                inputs: e.n_inputs,
                outputs: e.n_outputs,
            });
        }
        let samples = self.samples();
        if !inputs.iter().chain(outputs).all(|v| v.is_finite()) {
            self.set_state(FAILED, samples);
            return Err(Error::NotFinite { sample: samples });
        }
        // Each output once through its transform: `current` is asked for
        // a signal many times per sample.
        let mut taken = [0.0; MAX_SIGNALS];
        let mut untransformed = 0;
        for ((slot, y), j) in taken.iter_mut().zip(outputs).zip(0..) {
            *slot = e.output_sample(j, *y).unwrap_or_else(|floor| {
                untransformed += 1;
                floor
            });
        }
        let layout = Layout::of(e, self.window);
        let Parts {
            mut memory,
            marks,
            family,
            learned,
            linearized,
            ..
        } = layout.split(self.work);
        let mut count = self.status.get(3).copied().unwrap_or(0.0) + f64::from(untransformed);
        if self.window > 0 && !marks.is_empty() {
            // The window's count: the sample leaving it takes its own away.
            let slot = samples % self.window;
            if samples >= self.window {
                count -= marks.get(slot).copied().unwrap_or(0.0);
            }
            if let Some(mark) = marks.get_mut(slot) {
                *mark = f64::from(untransformed);
            }
        }
        if let Some(kept) = self.status.get_mut(3) {
            *kept = count;
        }
        // The signals as measured: the host summarizes the outputs before
        // any transform.
        let signals = inputs.iter().chain(outputs);
        for (words, u) in family.chunks_exact_mut(ACCUMULATOR_WORDS).zip(signals) {
            let mut kept = accumulator(words);
            kept.push(*u);
            for (w, k) in words.iter_mut().zip(kept.to_words()) {
                *w = k;
            }
        }
        if let (Some(network), 0) = (e.learned(), self.window) {
            network.push(learned, |j| measured(inputs, outputs, j));
        }
        if let Some(lin) = e.linearization() {
            let (kept, ring) = linearized.split_at_mut(CarStream::WORDS.min(linearized.len()));
            let mut car = CarStream::from_words(&first_words(kept));
            car.push(
                &lin,
                measured(inputs, outputs, 0),
                measured(inputs, outputs, 1),
            );
            let blocks = WindowBlocks::of(self.window);
            if self.window > 0 && (samples + 1).is_multiple_of(blocks.len) {
                // A block ends: its sums take their slot in the ring, and
                // the next block starts from none.
                let slot = ((samples + 1) / blocks.len - 1) % blocks.count;
                let at = slot * LinearizedSums::WORDS;
                if let Some(kept) = ring.get_mut(at..at + LinearizedSums::WORDS) {
                    kept.copy_from_slice(&car.sums.to_words());
                }
                car.sums = LinearizedSums::default();
            }
            for (k, w) in kept.iter_mut().zip(car.to_words()) {
                *k = w;
            }
        }
        let current = |signal: usize| -> f64 {
            if signal < e.n_outputs {
                taken.get(signal)
            } else {
                inputs.get(signal - e.n_outputs)
            }
            .copied()
            .unwrap_or(f64::NAN)
        };
        if e.has_linearized_stage1() {
            layout.shape.keep(samples, current, &mut memory);
        } else {
            layout.shape.push(samples, current, &mut memory);
        }
        self.set_samples(samples.saturating_add(1));
        Ok(())
    }

    /// Estimate from the samples so far: the features, the estimate (in
    /// the prior box) into `theta`, the record's interval half-widths into
    /// `half_widths` (when calibrated and it has room for q numbers; pass
    /// `&mut []` to skip them), and the out-of-distribution distance. The
    /// stream keeps its samples: push more and finish again for the
    /// longer record (a control unit can update its estimate as the data
    /// comes), or [`Stream::reset`] for the next record.
    ///
    /// # Errors
    /// [`Error::OutputTooShort`] for a `theta` shorter than q,
    /// [`Error::TooShort`] for too few samples, [`Error::RankDeficient`]
    /// for regressors the input does not excite, [`Error::Overflow`], and
    /// the error that stopped a push.
    pub fn finish(
        &mut self,
        theta: &mut [f64],
        half_widths: &mut [f64],
    ) -> Result<Assessment, Error> {
        let e = self.estimator;
        self.check_open()?;
        let q = e.n_parameters();
        let theta = theta
            .get_mut(..q)
            .ok_or(Error::OutputTooShort { needed: q })?;
        let n = e.per_output();
        let needed = e.min_samples();
        let pushed = self.samples();
        // The samples the sums hold: the record's, or the window's.
        let samples = match self.window {
            0 => pushed,
            window => pushed.min(window),
        };
        if samples < needed {
            return Err(Error::TooShort { samples, needed });
        }
        let layout = Layout::of(e, self.window);
        let Parts {
            memory,
            family,
            learned,
            linearized,
            features,
            scratch,
            ..
        } = layout.split(self.work);
        if self.window > 0 {
            // A signal at zero through the whole window leaves in its sums
            // the rounding of the products that left it, not zero: refused
            // as the host refuses a record with nothing to fit.
            let silent = |signal: usize| {
                (pushed - samples..pushed)
                    .all(|i| memory.sample(&layout.shape, signal, i).0.abs() <= 0.0)
            };
            let outputs = (0..e.n_outputs).filter(|_| e.na > 0).map(|i| (i, 0));
            let inputs = (0..e.n_inputs)
                .filter(|_| e.nb > 0)
                .map(|j| (e.n_outputs + j, e.na + j * e.nb));
            if let Some((_, column)) = outputs.chain(inputs).find(|(signal, _)| silent(*signal)) {
                return Err(Error::RankDeficient { output: 0, column });
            }
        }
        let rhs = packed(n, 0);
        let (arx, summary) = features.split_at_mut(e.arx_features().min(features.len()));
        let summary_len = if e.has_signal_summary() {
            SUMMARY_LEN * (e.n_inputs + e.n_outputs)
        } else {
            0
        };
        let (summary, learned_summary) = summary.split_at_mut(summary_len.min(summary.len()));
        // A linearized stage 1 has no ARX regression (n = 0).
        for (i, alpha) in arx.chunks_exact_mut(n.max(1)).enumerate() {
            // Column c of output i's regression: its own lags, then each
            // input's; the target is the output at lag 0.
            let column = |c: usize| -> (usize, usize) {
                if c < e.na {
                    (i, c + 1)
                } else {
                    let (j, l) = ((c - e.na) / e.nb, (c - e.na) % e.nb);
                    (e.n_outputs + j, e.delay + l)
                }
            };
            for r in 0..n {
                for c in 0..=r {
                    let g = layout
                        .shape
                        .entry(&memory, samples, pushed, column(r), column(c));
                    store(scratch, packed(r, c), g);
                }
                store(
                    scratch,
                    rhs + r,
                    layout
                        .shape
                        .entry(&memory, samples, pushed, column(r), (i, 0)),
                );
            }
            solve(scratch, n, alpha).map_err(|column| match column {
                Some(column) => Error::RankDeficient { output: i, column },
                None => Error::Overflow,
            })?;
        }
        // Each signal's summary, inputs first, in cycles per sample: a
        // record's from its accumulators, a window's from its samples.
        let signal_summary = |signal: usize| -> InputAccumulator {
            if self.window == 0 {
                return accumulator(family.get(signal * ACCUMULATOR_WORDS..).unwrap_or_default());
            }
            let column = if signal < e.n_inputs {
                e.n_outputs + signal
            } else {
                signal - e.n_inputs
            };
            let mut window = InputAccumulator::new();
            for i in pushed - samples..pushed {
                window.push(memory.sample(&layout.shape, column, i).0);
            }
            window
        };
        for (signal, numbers) in summary.chunks_exact_mut(SUMMARY_LEN).enumerate() {
            numbers.copy_from_slice(&signal_summary(signal).summary(1.0));
        }
        if let Some(network) = e.learned() {
            if self.window > 0 {
                // The window's samples, oldest first, through a network
                // that starts afresh: the window's summary as the host's
                // of the window alone.
                learned.fill(0.0);
                for i in pushed - samples..pushed {
                    network.push(learned, |j| {
                        let column = if j < e.n_inputs {
                            e.n_outputs + j
                        } else {
                            j - e.n_inputs
                        };
                        memory.sample(&layout.shape, column, i).0
                    });
                }
            }
            if !network.finish(learned, learned_summary) {
                return Err(Error::TooShort { samples, needed });
            }
        }
        if let Some(lin) = e.linearization() {
            let (kept, ring) = linearized.split_at_mut(CarStream::WORDS.min(linearized.len()));
            let mut sums = LinearizedSums::default();
            if self.window > 0 {
                let blocks = WindowBlocks::of(self.window);
                for block in blocks.summed(pushed) {
                    let at = (block % blocks.count) * LinearizedSums::WORDS;
                    sums.merge(&LinearizedSums::from_words(&first_words(
                        ring.get(at..).unwrap_or_default(),
                    )));
                }
            }
            // A record's sums, or the window's current block's.
            sums.merge(&CarStream::from_words(&first_words(kept)).sums);
            lin.features(&sums, learned_summary)
                .ok_or(Error::Overflow)?;
        }
        predict(e, features, scratch, theta)?;
        for (j, t) in theta.iter_mut().enumerate() {
            if e.is_log(j) {
                *t = libm::exp(*t);
            }
        }
        clip_to_box(theta, &e.lower, &e.upper);
        let intervals = match (e.adaptive, e.conformal, half_widths.get_mut(..q)) {
            (Some(adaptive), _, Some(widths)) => {
                adaptive.difficulty.predict(features, scratch, widths)?;
                for (j, w) in widths.iter_mut().enumerate() {
                    let floor = adaptive.floor.at(j);
                    let sigma = if w.is_nan() { floor } else { w.max(floor) };
                    *w = adaptive.quantile.at(j) * sigma;
                }
                Intervals::Adaptive
            }
            (None, Some(conformal), Some(widths)) => {
                for (j, w) in widths.iter_mut().enumerate() {
                    *w = conformal.at(j);
                }
                Intervals::Conformal
            }
            _ => Intervals::None,
        };
        let feature_distance = e.envelope.map(|envelope| {
            let z = scratch.get_mut(..features.len()).unwrap_or_default();
            for (j, (z, x)) in z.iter_mut().zip(features.iter()).enumerate() {
                *z = x - envelope.mean.at(j);
            }
            solve_lower_in_place(&envelope.factor, features.len(), z);
            libm::sqrt(z.iter().map(|v| v * v).sum::<f64>())
        });
        Ok(Assessment {
            intervals,
            feature_distance,
            distance_threshold: e.envelope.map(|envelope| envelope.threshold),
            untransformed_samples: self.status.get(3).map_or(0, |c| *c as usize),
            // The window's inputs, oldest first, as the host summarizes the
            // window alone.
            input_outside_family: input_outside_family(e, signal_summary),
        })
    }
}

/// The first `N` numbers of `kept` (zeros past its end).
fn first_words<const N: usize>(kept: &[f64]) -> [f64; N] {
    let mut out = [0.0; N];
    for (o, k) in out.iter_mut().zip(kept) {
        *o = *k;
    }
    out
}

/// Signal `j` of a sample as measured, inputs first.
fn measured(inputs: &[f64], outputs: &[f64], j: usize) -> f64 {
    match j.checked_sub(inputs.len()) {
        None => inputs.get(j),
        Some(k) => outputs.get(k),
    }
    .copied()
    .unwrap_or(f64::NAN)
}

/// The learning-space estimate of the features.
fn predict(
    e: &Estimator<'_>,
    features: &[f64],
    scratch: &mut [f64],
    out: &mut [f64],
) -> Result<(), Error> {
    match e.regressor {
        Regressor::Network(network) => network.predict(features, scratch, out),
        Regressor::Piecewise {
            global,
            start,
            width,
            count,
            ..
        } => {
            global.predict(features, scratch, out)?;
            let position = (out.first().copied().unwrap_or(f64::NAN) - start) / width;
            // NaN and out-of-range positions go to the nearest piece.
            let piece = if position.is_nan() {
                0
            } else {
                (position.max(0.0) as usize).min(count.saturating_sub(1))
            };
            let expert = e.expert(piece).ok_or(Error::Invalid {
                field: "expert",
                at: 0,
            })?;
            expert.predict(features, scratch, out)
        }
    }
}

impl Estimator<'_> {
    /// How many `f64` a [`crate::Stream`] of this estimator needs as its
    /// workspace: the past samples of each signal, the normal equations
    /// of each output in double-double, each input's summary (for an
    /// estimator with an input family), and the scratch of the final
    /// solve and networks.
    pub fn workspace_len(&self) -> usize {
        Layout::of(self, 0).total
    }

    /// How many `f64` a [`Stream::window`] of `window` samples needs: each
    /// signal's samples in the window, the normal equations, the scratch
    /// (and a count per sample, for an estimator that transforms its
    /// outputs).
    pub fn window_workspace_len(&self, window: usize) -> usize {
        Layout::of(self, window).total
    }
}
