//! The compressed data chart: simulate and compress in one pass.

use ndarray::Array2;
use rayon::prelude::*;
use twostage_compress::{Compressor, CompressorConfig, Workspace};
use twostage_models::{Design, InputFamily, IoData, ModelSpec, Simulator, run_experiments};

use crate::error::{Error, Result};
use crate::progress::{Progress, Stage};

/// One experiment that could not be simulated or compressed.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentFailure {
    /// Its index in the design.
    pub index: usize,
    /// Its parameter vector.
    pub theta: Vec<f64>,
    /// What went wrong.
    pub error: String,
}

/// The compressed artificial data chart of Table II: for each experiment i,
/// its parameter vector theta_i and its features alpha_i.
///
/// Only `(theta_i, alpha_i)` is kept: records are compressed as they are
/// simulated, so memory is O(m n), never O(m N).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CompressedChart {
    /// Parameter vectors of the experiments that succeeded (m' x q).
    pub thetas: Array2<f64>,
    /// Their features (m' x n).
    pub features: Array2<f64>,
    /// Design indices of the rows, in order.
    pub indices: Vec<usize>,
    /// Experiments that failed, in index order.
    pub failures: Vec<ExperimentFailure>,
    /// The family the kept records' inputs span (simulated, read from
    /// files or from shards alike; `None` for a chart made by hand).
    pub inputs: Option<InputFamily>,
}

/// Simulate and compress every experiment of `design` in parallel.
///
/// Row i depends only on `(design, i)`: the chart is bitwise identical
/// whatever the thread count.
///
/// ```
/// use twostage_sources::compress_chart;
/// use twostage_compress::Arx;
/// use twostage_models::{Benchmark, Simulator};
/// let model = Benchmark::new();
/// let design = model.prior().design(64, 1)?;
/// let chart = compress_chart(&model, &Arx::new(2, 2)?, &design, "training", 0.0)?;
/// assert_eq!(chart.features.dim(), (64, 4));
/// assert_eq!(chart.thetas.dim(), (64, 1));
/// # Ok::<(), twostage_sources::Error>(())
/// ```
///
/// # Errors
/// [`Error::TooManyFailures`] if more than `max_failure_fraction` of the
/// experiments fail (failures below that are dropped and listed).
pub fn compress_chart<S, C>(
    simulator: &S,
    compressor: &C,
    design: &Design,
    stage: &'static str,
    max_failure_fraction: f64,
) -> Result<CompressedChart>
where
    S: Simulator + ?Sized,
    C: Compressor + ?Sized,
{
    simulate_and_compress(
        simulator,
        compressor,
        (design, 0..design.len(), true),
        stage,
        max_failure_fraction,
        |_| {},
    )
}

/// [`compress_chart`] of the experiments `range` of `design` (their
/// indices the design's), for one stage of a training run, telling
/// `progress` of each finished experiment; the failure allowance is
/// taken on the range alone. The records' input family is summarized
/// where `family` asks for it (it costs about as much as compressing).
pub(crate) fn compress_chart_observed<S, C>(
    simulator: &S,
    compressor: &C,
    rows: (&Design, std::ops::Range<usize>, bool),
    stage: Stage,
    max_failure_fraction: f64,
    progress: &dyn Progress,
) -> Result<CompressedChart>
where
    S: Simulator + ?Sized,
    C: Compressor + ?Sized,
{
    progress.begin(stage, rows.1.len());
    let chart = simulate_and_compress(
        simulator,
        compressor,
        rows,
        stage.label(),
        max_failure_fraction,
        |_| progress.advance(stage, 1),
    );
    progress.end(stage);
    chart
}

fn simulate_and_compress<S, C>(
    simulator: &S,
    compressor: &C,
    (design, range, family): (&Design, std::ops::Range<usize>, bool),
    stage: &'static str,
    max_failure_fraction: f64,
    finished: impl Fn(usize) + Sync,
) -> Result<CompressedChart>
where
    S: Simulator + ?Sized,
    C: Compressor + ?Sized,
{
    let (first, m) = (range.start, range.len());
    let q = design.prior().dim();
    let n = compressor.n_features();
    let mut thetas = vec![0.0; m * q];
    let mut features = vec![0.0; m * n];
    // Blocks of the simulator's batch size (1 unless it vectorizes): the
    // bits of experiment i do not depend on the block it is in.
    let block = simulator.batch_size().max(1);
    let spec = simulator.spec();
    let (n_u, dt) = (spec.input_names().len(), spec.sample_time());
    let outcomes: Vec<(Vec<ExperimentFailure>, InputFamily)> = thetas
        .par_chunks_mut(q * block)
        .zip(features.par_chunks_mut(n * block))
        .enumerate()
        .map_init(
            || (Vec::<IoData>::new(), Workspace::new()),
            |(records, work), (c, (theta_block, alpha_block))| {
                let start = first + c * block;
                let len = theta_block.len() / q;
                records.resize_with(len, IoData::default);
                let simulated =
                    run_experiments(simulator, design, start, theta_block, &mut records[..len]);
                let mut failed = Vec::new();
                let mut inputs = InputFamily::new(n_u, dt);
                for (k, outcome) in simulated.into_iter().enumerate() {
                    let record = &records[k];
                    let alpha = &mut alpha_block[k * n..(k + 1) * n];
                    let outcome = outcome.map_err(|e| e.to_string()).and_then(|()| {
                        compressor
                            .compress_into(record.inputs(), record.outputs(), work, alpha)
                            .map_err(|e| e.to_string())
                    });
                    finished(start + k);
                    match outcome {
                        Ok(()) if family => inputs.include(record),
                        Ok(()) => {}
                        Err(error) => failed.push(ExperimentFailure {
                            index: start + k,
                            theta: theta_block[k * q..(k + 1) * q].to_vec(),
                            error,
                        }),
                    }
                }
                (failed, inputs)
            },
        )
        .collect();
    // Ranges merge in any order to the same bits: the family does not
    // depend on the thread count.
    let mut inputs = InputFamily::new(n_u, dt);
    let mut failures = Vec::new();
    for (failed, block_inputs) in outcomes {
        failures.extend(failed);
        inputs.merge(&block_inputs);
    }
    within_allowance(stage, &failures, m, max_failure_fraction)?;
    let failed: Vec<usize> = failures.iter().map(|f| f.index).collect();
    let indices: Vec<usize> = range.filter(|i| failed.binary_search(i).is_err()).collect();
    let keep = |values: Vec<f64>, width: usize| -> Array2<f64> {
        let rows = indices.len();
        let mut kept = Vec::with_capacity(rows * width);
        for &i in &indices {
            let at = i - first;
            kept.extend_from_slice(&values[at * width..(at + 1) * width]);
        }
        Array2::from_shape_vec((rows, width), kept)
            .unwrap_or_else(|_| unreachable!("rows * width values were kept"))
    };
    Ok(CompressedChart {
        thetas: keep(thetas, q),
        features: keep(features, n),
        indices,
        failures,
        inputs: family.then_some(inputs),
    })
}

impl CompressedChart {
    /// Experiments tried: kept and failed.
    pub fn total(&self) -> usize {
        self.indices.len() + self.failures.len()
    }

    /// `more`'s rows after these: the chart of two ranges of one design,
    /// compressed by one compressor, `more`'s following this one's.
    pub(crate) fn extend(&mut self, more: CompressedChart) {
        let stack = |a: &Array2<f64>, b: &Array2<f64>| {
            ndarray::concatenate(ndarray::Axis(0), &[a.view(), b.view()])
                .unwrap_or_else(|_| unreachable!("one compressor's rows are of one width"))
        };
        self.thetas = stack(&self.thetas, &more.thetas);
        self.features = stack(&self.features, &more.features);
        self.indices.extend(more.indices);
        self.failures.extend(more.failures);
        match (self.inputs.as_mut(), more.inputs) {
            (Some(all), Some(family)) => all.merge(&family),
            (None, family) => self.inputs = family,
            (Some(_), None) => {}
        }
    }
}

/// Refuse a chart whose failures exceed `max_failure_fraction` of `total`
/// experiments (`failures` in index order), naming the first.
pub(crate) fn within_allowance(
    stage: &'static str,
    failures: &[ExperimentFailure],
    total: usize,
    max_failure_fraction: f64,
) -> Result<()> {
    let allowed = (max_failure_fraction * total as f64).floor() as usize;
    match failures.first() {
        Some(first) if failures.len() > allowed => Err(Error::TooManyFailures {
            stage,
            failed: failures.len(),
            total,
            allowed,
            first_index: first.index,
            first_error: first.error.clone(),
        }),
        _ => Ok(()),
    }
}

/// One simulated experiment: its parameter vector and record, or why it
/// failed.
pub(crate) type Outcome = std::result::Result<(Vec<f64>, IoData), ExperimentFailure>;

/// Simulate experiments `range` of `design` in parallel, in blocks of the
/// simulator's batch size, and return their outcomes in index order.
/// `progress`, when given, hears of each finished experiment under its
/// stage. Record i depends only on `(design, i)`, not on the range.
pub(crate) fn simulate_range<S: Simulator + ?Sized>(
    simulator: &S,
    design: &Design,
    range: std::ops::Range<usize>,
    progress: Option<(Stage, &dyn Progress)>,
) -> Vec<Outcome> {
    let q = design.prior().dim();
    if let Some((stage, progress)) = progress {
        progress.begin(stage, range.len());
    }
    let block = simulator.batch_size().max(1);
    let outcomes: Vec<Outcome> = (0..range.len().div_ceil(block))
        .into_par_iter()
        .map(|c| {
            let start = range.start + c * block;
            let len = block.min(range.end - start);
            let (mut thetas, mut records) = (vec![0.0; len * q], vec![IoData::default(); len]);
            let simulated = run_experiments(simulator, design, start, &mut thetas, &mut records);
            if let Some((stage, progress)) = progress {
                progress.advance(stage, len);
            }
            simulated
                .into_iter()
                .zip(thetas.chunks_exact(q).zip(records))
                .enumerate()
                .map(|(k, (outcome, (theta, record)))| match outcome {
                    Ok(()) => Ok((theta.to_vec(), record)),
                    Err(e) => Err(ExperimentFailure {
                        index: start + k,
                        theta: theta.to_vec(),
                        error: e.to_string(),
                    }),
                })
                .collect::<Vec<_>>()
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    if let Some((stage, progress)) = progress {
        progress.end(stage);
    }
    outcomes
}

/// A chart kept whole: parameter vectors and full records, for the
/// automatic design (which compresses one chart many ways) and for fitting
/// a compressor's own parameters (PCA directions, NARX scales).
pub struct StoredChart {
    /// Parameter vectors of the experiments that succeeded (m' x q).
    pub thetas: Array2<f64>,
    /// Their records, in design order.
    pub records: Vec<IoData>,
}

/// Simulate the first `count` experiments of `design` in parallel and keep
/// their records; failed experiments are dropped within
/// `max_failure_fraction`. `progress`, when given, hears of each finished
/// experiment under its stage. Record i depends only on `(design, i)`.
/// # Errors
/// [`Error::TooManyFailures`] beyond the allowance.
pub fn simulate_records<S: Simulator + ?Sized>(
    simulator: &S,
    design: &Design,
    count: usize,
    max_failure_fraction: f64,
    progress: Option<(Stage, &dyn Progress)>,
) -> Result<StoredChart> {
    simulate_stored(
        simulator,
        design,
        0..count.min(design.len()),
        max_failure_fraction,
        progress,
    )
}

/// [`simulate_records`] of the experiments `range` of `design`, the
/// allowance taken on the range alone.
pub(crate) fn simulate_stored<S: Simulator + ?Sized>(
    simulator: &S,
    design: &Design,
    range: std::ops::Range<usize>,
    max_failure_fraction: f64,
    progress: Option<(Stage, &dyn Progress)>,
) -> Result<StoredChart> {
    let count = range.len();
    let q = design.prior().dim();
    let outcomes = simulate_range(simulator, design, range, progress);
    let stage = progress.map_or("simulation", |(stage, _)| stage.label());
    let (mut thetas, mut records, mut failures) = (Vec::new(), Vec::new(), Vec::new());
    for outcome in outcomes {
        match outcome {
            Ok((theta, record)) => {
                thetas.extend(theta);
                records.push(record);
            }
            Err(failure) => failures.push(failure),
        }
    }
    within_allowance(stage, &failures, count, max_failure_fraction)?;
    Ok(StoredChart {
        thetas: Array2::from_shape_vec((records.len(), q), thetas)
            .unwrap_or_else(|_| unreachable!("q values per kept record")),
        records,
    })
}

/// A stage-1 compressor fitted to a model's records: shaped for its
/// signals and length, prepared on its whole records.
pub trait ForModel: Sized {
    /// The same compressor for the records of `spec`'s model.
    ///
    /// # Errors
    /// A structure the model's signals cannot take.
    fn for_model(&self, spec: &ModelSpec) -> Result<Self>;
    /// The compressor with its own parameters fitted on `records`.
    ///
    /// # Errors
    /// What fitting those parameters reports.
    fn prepared_on(&self, records: &[IoData]) -> Result<Self>;
    /// The compressor with its summary network (a `+learned` stage 1)
    /// trained end to end on `records` and their parameter vectors
    /// `thetas` (row i is record i's, in the prior's own coordinates),
    /// seeded by `seed`, no epoch started after `stop_by`; as it is when
    /// it has no untrained network. Its other fitted parts must be
    /// prepared first ([`Self::prepared_on`]).
    ///
    /// # Errors
    /// Records that do not match `thetas` or cannot train the network
    /// (too short for its receptive field, a signal that never moves).
    fn trained_on(
        &self,
        thetas: ndarray::ArrayView2<'_, f64>,
        records: &[IoData],
        seed: u64,
        stop_by: Option<std::time::Instant>,
    ) -> Result<Self>;
}

impl ForModel for CompressorConfig {
    fn for_model(&self, spec: &ModelSpec) -> Result<Self> {
        let shaped = self.for_shape(
            spec.input_names().len(),
            spec.output_names().len(),
            spec.n_samples(),
        )?;
        if !shaped.needs_equations() {
            return Ok(shaped);
        }
        let Some(equations) = spec.car_equations() else {
            return Err(Error::InvalidSetting(crate::InvalidSetting {
                name: "compressor",
                value: self.to_string(),
                reason: format!(
                    "the linearized stage 1 needs a model whose equations twostage holds (the \
                 built-in car, or a model file of it with its parameters pK1, pK2); {} is \
                 not one: use arx, narx or pca",
                    spec.name()
                ),
            }));
        };
        let (lower, upper) = (spec.prior().lower(), spec.prior().upper());
        Ok(shaped.for_car(
            equations.car,
            [lower[0], lower[1]],
            [upper[0], upper[1]],
            equations.noise_variance,
            spec.sample_time(),
        )?)
    }

    fn prepared_on(&self, records: &[IoData]) -> Result<Self> {
        Ok(self.prepared(records.iter().map(|r| (r.inputs(), r.outputs())))?)
    }

    fn trained_on(
        &self,
        thetas: ndarray::ArrayView2<'_, f64>,
        records: &[IoData],
        seed: u64,
        stop_by: Option<std::time::Instant>,
    ) -> Result<Self> {
        let Some(shape) = self.untrained_summary() else {
            return Ok(self.clone());
        };
        // Inputs, then outputs, side by side: the network's channels.
        let signals: Vec<Array2<f64>> = records
            .iter()
            .map(|r| {
                let (u, y) = (r.inputs(), r.outputs());
                let n_u = u.ncols();
                Array2::from_shape_fn((y.nrows(), n_u + y.ncols()), |(k, j)| {
                    if j < n_u { u[[k, j]] } else { y[[k, j - n_u]] }
                })
            })
            .collect();
        let training = twostage_fit::SummaryTraining {
            shape: shape.clone(),
            seed,
            stop_by,
            ..twostage_fit::SummaryTraining::default()
        };
        let trained = training.train(&signals, thetas)?;
        Ok(self.with_trained_summary(trained.network)?)
    }
}
