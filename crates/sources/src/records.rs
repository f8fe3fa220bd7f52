//! Where the records of a training run come from: simulated on the fly,
//! read from chart files, or merged from shards. The builder's one `train`
//! asks its source for the compressed records of each role
//! ([`ChartRole`]) and never knows which source it reads.

use crate::InvalidSetting;
use std::cell::RefCell;

use twostage_compress::{Compressor, Workspace};
use twostage_models::{InputFamily, IoData, ModelSpec, Prior, RecordsOrigin, Sampling, Simulator};

use crate::chart::{
    CompressedChart, ExperimentFailure, ForModel, StoredChart, compress_chart_observed,
    simulate_records, simulate_stored, within_allowance,
};
use crate::chart_file::ChartFiles;
use crate::error::{Error, Result};
use crate::progress::{Progress, Stage};
use crate::readable::refuse_beyond_memory;
use crate::roles::{ChartRole, RoleCounts, held_out_roles};
use crate::shard::ShardedChart;
use twostage_compress::CompressorConfig;

/// Where the records of a training run come from (the facade's builder
/// reads them through [`Records`]).
#[derive(Debug, Clone, Copy, Default)]
pub enum RecordSource<'c> {
    /// Simulated by the builder's simulator: the training chart from the
    /// prior as it samples, the calibration and validation charts i.i.d.
    /// from it with streams of their own ([`ChartRole::design`]).
    #[default]
    Simulated,
    /// A chart simulated elsewhere ([`ChartFiles`]); calibration and
    /// validation on their own charts when given, else on records held out
    /// of the training chart at random (seeded), as many as the builder's
    /// calibration and validation sizes say. The certificate then covers
    /// records drawn as the chart's were.
    Files {
        /// The training chart.
        training: &'c ChartFiles,
        /// A chart of its own for the conformal intervals.
        calibration: Option<&'c ChartFiles>,
        /// A chart of its own for the validation report.
        validation: Option<&'c ChartFiles>,
    },
    /// A chart simulated in shards ([`ShardedChart`], e.g. by a Slurm
    /// array): its seed and sizes are the run's, and the estimator is, bit
    /// for bit, the one the same run gives on simulated records.
    Shards(&'c ShardedChart),
}

impl RecordSource<'_> {
    /// Whether the records are simulated as the run goes.
    pub fn simulates(&self) -> bool {
        matches!(self, Self::Simulated)
    }
}

/// The stage of a run that reads the records of `role`.
fn stage(role: ChartRole) -> Stage {
    match role {
        ChartRole::Training => Stage::Training,
        ChartRole::Calibration => Stage::Calibration,
        ChartRole::Validation => Stage::Validation,
    }
}

/// A source opened for one run: it knows the run's sizes, seed and
/// failure allowance, and hands out each role's records compressed.
pub struct Records<'a, S: ?Sized> {
    simulator: &'a S,
    kind: Kind<'a>,
    training_prior: Prior,
    /// Records of the training, calibration and validation roles.
    counts: RoleCounts,
    seed: u64,
    max_failure_fraction: f64,
    progress: &'a dyn Progress,
}

enum Kind<'a> {
    Simulated,
    Files {
        chart: &'a ChartFiles,
        /// Charts of their own, by role slot (none for training).
        own: [Option<&'a ChartFiles>; 3],
        /// The role of each row of `chart`.
        roles: Vec<ChartRole>,
        /// `chart` compressed, by role slot, once the first role asks.
        parts: RefCell<Option<Vec<CompressedChart>>>,
    },
    Shards(&'a ShardedChart),
}

/// What a run tells its source.
pub struct RunShape<'a> {
    /// The prior the training records are drawn from, as it samples.
    pub training_prior: Prior,
    /// Training simulations, calibration and validation records asked for.
    pub counts: RoleCounts,
    /// The run's seed.
    pub seed: u64,
    /// Share of failed records tolerated per role.
    pub max_failure_fraction: f64,
    /// Who hears of each simulated record.
    pub progress: &'a dyn Progress,
}

impl<'a, S: Simulator + ?Sized> Records<'a, S> {
    /// Open `source` for a run of `shape` on `simulator`'s model.
    ///
    /// # Errors
    /// A chart too small for the records it must hold out.
    pub fn open(simulator: &'a S, source: RecordSource<'a>, shape: RunShape<'a>) -> Result<Self> {
        let RunShape {
            training_prior,
            mut counts,
            seed,
            max_failure_fraction,
            progress,
        } = shape;
        let kind = match source {
            RecordSource::Simulated => Kind::Simulated,
            RecordSource::Shards(chart) => Kind::Shards(chart),
            RecordSource::Files {
                training,
                calibration,
                validation,
            } => {
                let m = training.len();
                let held_calibration = if calibration.is_some() {
                    0
                } else {
                    counts.calibration
                };
                let held_validation = if validation.is_some() {
                    0
                } else {
                    counts.validation
                };
                let held = held_validation + held_calibration;
                if m < held + 10 {
                    return Err(Error::InvalidSetting(InvalidSetting {
                        name: "held-out records",
                        value: format!(
                            "{held_validation} validation + {held_calibration} calibration"
                        ),
                        reason: format!(
                            "the chart {} has {m} records: at least 10 must be left to train on \
                             (hold out fewer, or give separate validation and calibration charts)",
                            training.describe()
                        ),
                    }));
                }
                counts = RoleCounts::new(m - held, held_calibration, held_validation);
                Kind::Files {
                    chart: training,
                    own: [None, calibration, validation],
                    roles: held_out_roles(m, held_validation, held_calibration, seed),
                    parts: RefCell::new(None),
                }
            }
        };
        Ok(Self {
            simulator,
            kind,
            training_prior,
            counts,
            seed,
            max_failure_fraction,
            progress,
        })
    }

    fn spec(&self) -> &ModelSpec {
        self.simulator.spec()
    }

    /// `compressor` with its own parameters (an output PCA's directions, a
    /// NARX's signal scales) fitted on the first training records, or as
    /// it is when it has none. Compressed shards must have been compressed
    /// by this very compressor.
    ///
    /// # Errors
    /// Compressed shards of another compressor, a failed preparation.
    pub fn prepare(&self, compressor: CompressorConfig) -> Result<CompressorConfig> {
        let prepared = self.prepare_fitted_parts(compressor)?;
        match prepared.untrained_summary() {
            Some(_) => self.train_summary(&prepared),
            None => Ok(prepared),
        }
    }

    /// `compressor` with its summary network trained on the training
    /// records and their parameters (the run's seed), for a `+learned`
    /// stage 1.
    fn train_summary(&self, compressor: &CompressorConfig) -> Result<CompressorConfig> {
        // The simulations are heard of as they run; the network's epochs
        // as one step of no count.
        let (StoredChart { thetas, records }, _) = self.stored_training_for(Stage::Learning)?;
        self.progress.begin(Stage::Learning, 0);
        let trained = compressor.trained_on(thetas.view(), &records, self.seed, None);
        self.progress.end(Stage::Learning);
        trained
    }

    /// `compressor` with the parts fitted on the first training records
    /// (a PCA's directions, a NARX's scales, a transform's floor).
    fn prepare_fitted_parts(&self, compressor: CompressorConfig) -> Result<CompressorConfig> {
        let count = compressor.records_to_prepare();
        match &self.kind {
            Kind::Shards(chart) => match &chart.plan().compressor {
                Some(stored_text) => {
                    let stored: CompressorConfig = stored_text.parse()?;
                    if stored.for_model(self.spec())? != compressor {
                        return Err(Error::Shards {
                            what: chart.pattern().to_string(),
                            message: format!(
                                "the shards hold features of {stored_text}, the training asks \
                                 for {compressor}: train with --compress {stored_text} (or \
                                 simulate raw shards)"
                            ),
                        });
                    }
                    Ok(compressor)
                }
                None if count > 0 => compressor.prepared_on(&chart.first_training_records(count)?),
                None => Ok(compressor),
            },
            _ if count == 0 => Ok(compressor),
            Kind::Simulated => {
                let design = ChartRole::Training.design(
                    &self.training_prior,
                    self.counts.training,
                    self.seed,
                )?;
                let chart = simulate_records(self.simulator, &design, count, 0.0, None)?;
                compressor.prepared_on(&chart.records)
            }
            Kind::Files { chart, roles, .. } => {
                // The first `count` training rows of the chart, whatever
                // the order its records are stored in.
                let wanted: Vec<usize> = (0..chart.len())
                    .filter(|row| roles[*row] == ChartRole::Training)
                    .take(count)
                    .collect();
                let mut first: Vec<(usize, IoData)> = Vec::with_capacity(wanted.len());
                chart.for_each_record(self.spec(), |row, record| {
                    if wanted.binary_search(&row).is_ok() {
                        first.push((row, record.clone()));
                    }
                    Ok(())
                })?;
                first.sort_by_key(|(row, _)| *row);
                let records: Vec<IoData> = first.into_iter().map(|(_, r)| r).collect();
                compressor.prepared_on(&records)
            }
        }
    }

    /// The records of `role` compressed by `compressor`, rows in design
    /// (or chart) order, failures listed and held within the run's
    /// allowance; `None` when the run has no records of that role.
    ///
    /// # Errors
    /// Too many failed records, or a file problem of the source.
    pub fn compressed(
        &self,
        role: ChartRole,
        compressor: &CompressorConfig,
    ) -> Result<Option<CompressedChart>> {
        let count = self.counts[role];
        let chart = match &self.kind {
            Kind::Files { own, .. } if own[role.slot()].is_some() => {
                let given = own[role.slot()].unwrap_or_else(|| unreachable!("checked above"));
                let mut parts = chart_parts(self.spec(), compressor, given, None)?;
                parts.swap_remove(0)
            }
            _ if count == 0 => return Ok(None),
            Kind::Simulated => {
                // The design, the parameters and the features, each a row
                // of f64 per record, before the fit copies them.
                let q = self.training_prior.dim() as u64;
                let each = 8 * (2 * q + compressor.n_features() as u64);
                let name = match role {
                    ChartRole::Training => "simulations",
                    other => other.label(),
                };
                let taken = refuse_beyond_memory(
                    name,
                    count,
                    each,
                    &format!("{} records' parameters and features", role.label()),
                )?;
                self.progress.note(&taken);
                let design = role.design(&self.training_prior, count, self.seed)?;
                return compress_chart_observed(
                    self.simulator,
                    compressor,
                    (&design, 0..count, true),
                    stage(role),
                    self.max_failure_fraction,
                    self.progress,
                )
                .map(Some);
            }
            Kind::Shards(chart) => chart.compressed(role, compressor)?,
            Kind::Files {
                chart,
                roles,
                parts,
                ..
            } => {
                let mut parts = parts.borrow_mut();
                if parts.is_none() {
                    // One pass over the files compresses every role.
                    *parts = Some(chart_parts(self.spec(), compressor, chart, Some(roles))?);
                }
                let part = parts.as_mut().map(|p| std::mem::take(&mut p[role.slot()]));
                part.unwrap_or_else(|| unreachable!("compressed above"))
            }
        };
        within_allowance(
            role.label(),
            &chart.failures,
            chart.total(),
            self.max_failure_fraction,
        )?;
        Ok(Some(chart))
    }

    /// Whether the records of `role` can grow past the run's count: only
    /// simulated ones, whose design extends with the same rows.
    pub fn grows(&self, role: ChartRole) -> bool {
        matches!(self.kind, Kind::Simulated) && role != ChartRole::Training
    }

    /// `chart`, the records of `role` as [`Self::compressed`] gave them,
    /// grown to `to` experiments of the same design: the chart a run of
    /// `to` records of that role would have given, bit for bit, but for
    /// its input family, which stays the first records' (the new ones'
    /// inputs are not summarized). A source that cannot grow
    /// ([`Self::grows`]) leaves it as it is.
    ///
    /// # Errors
    /// Records that would not fit in memory, too many failed records among
    /// the new ones, or a malformed prior.
    pub fn grow(
        &self,
        role: ChartRole,
        compressor: &CompressorConfig,
        chart: &mut CompressedChart,
        to: usize,
    ) -> Result<()> {
        let from = chart.total();
        if !self.grows(role) || to <= from {
            return Ok(());
        }
        let q = self.training_prior.dim() as u64;
        let each = 8 * (q + compressor.n_features() as u64);
        // The setting that let the chart grow is the one to lower.
        let name = match role {
            ChartRole::Validation => "max_validation",
            other => other.label(),
        };
        refuse_beyond_memory(
            name,
            to,
            each,
            &format!("{} records' parameters and features", role.label()),
        )?;
        let design = role.design(&self.training_prior, to, self.seed)?;
        let more = compress_chart_observed(
            self.simulator,
            compressor,
            (&design, from..to, false),
            stage(role),
            self.max_failure_fraction,
            self.progress,
        )?;
        chart.extend(more);
        Ok(())
    }

    /// Every training record, uncompressed, with its parameters, in design
    /// (or chart) order, and how many experiments failed: for an automatic
    /// design, which compresses them many ways. Simulated records are
    /// simulated now (the run's training count, with progress); failed
    /// ones are held within the run's allowance.
    ///
    /// # Errors
    /// Too many failed records, shards that hold features, or a file
    /// problem of the source.
    pub fn stored_training(&self) -> Result<(StoredChart, usize)> {
        self.stored_training_for(Stage::Training)
    }

    /// [`Self::stored_training`], its simulations heard of under `stage`.
    fn stored_training_for(&self, stage: Stage) -> Result<(StoredChart, usize)> {
        let count = self.counts.training;
        match &self.kind {
            Kind::Simulated => {
                let design = ChartRole::Training.design(&self.training_prior, count, self.seed)?;
                let chart = simulate_records(
                    self.simulator,
                    &design,
                    count,
                    self.max_failure_fraction,
                    Some((stage, self.progress)),
                )?;
                let failed = count - chart.records.len();
                Ok((chart, failed))
            }
            Kind::Shards(chart) => {
                let (stored, failures) = chart.training_records()?;
                within_allowance(
                    ChartRole::Training.label(),
                    &failures,
                    stored.records.len() + failures.len(),
                    self.max_failure_fraction,
                )?;
                Ok((stored, failures.len()))
            }
            Kind::Files { chart, roles, .. } => {
                let q = self.spec().n_params();
                let mut kept: Vec<(usize, IoData)> = Vec::with_capacity(count);
                chart.for_each_record(self.spec(), |row, record| {
                    if roles[row] == ChartRole::Training {
                        kept.push((row, record.clone()));
                    }
                    Ok(())
                })?;
                kept.sort_by_key(|(row, _)| *row);
                let thetas: Vec<f64> = kept
                    .iter()
                    .flat_map(|(row, _)| chart.theta(*row).iter().copied())
                    .collect();
                let records: Vec<IoData> = kept.into_iter().map(|(_, r)| r).collect();
                let thetas = ndarray::Array2::from_shape_vec((records.len(), q), thetas)
                    .unwrap_or_else(|_| unreachable!("q values per kept record"));
                Ok((StoredChart { thetas, records }, 0))
            }
        }
    }

    /// Whether [`Self::more_training`] can simulate more training records:
    /// the source simulates, and its sampling draws each experiment on its
    /// own (uniform draws or Sobol points, where the first experiments of
    /// a larger design are the smaller design's; a Latin hypercube of more
    /// experiments is another design).
    pub fn can_grow(&self) -> bool {
        matches!(self.kind, Kind::Simulated)
            && !matches!(self.training_prior.sampling(), Sampling::LatinHypercube)
    }

    /// The training experiments `from..to` of the run's design, simulated
    /// now with progress, and how many of them failed (held within the
    /// run's allowance on these alone): appended to the first `from` of
    /// [`Self::stored_training`], they are the chart a run of `to`
    /// training simulations stores. `None` where the source cannot grow
    /// ([`Self::can_grow`]).
    ///
    /// # Errors
    /// Too many failed records, or a malformed prior.
    pub fn more_training(&self, from: usize, to: usize) -> Result<Option<(StoredChart, usize)>> {
        if !self.can_grow() || to <= from {
            return Ok(None);
        }
        let design = ChartRole::Training.design(&self.training_prior, to, self.seed)?;
        let chart = simulate_stored(
            self.simulator,
            &design,
            from..to,
            self.max_failure_fraction,
            Some((Stage::Training, self.progress)),
        )?;
        let failed = (to - from) - chart.records.len();
        Ok(Some((chart, failed)))
    }

    /// Training records the run has (simulated: asked for; read: those
    /// left after the held-out ones).
    pub fn training_count(&self) -> usize {
        self.counts.training
    }

    /// How the training records were drawn, for the estimator's record
    /// ([`RecordsOrigin`]'s line): the sampling design, or the chart.
    pub fn sampling(&self) -> String {
        match &self.kind {
            Kind::Simulated => RecordsOrigin::Drawn(self.training_prior.sampling()).line(),
            Kind::Shards(chart) => RecordsOrigin::Drawn(chart.sampling()).line(),
            Kind::Files { chart, own, .. } => {
                let source = |role: ChartRole| match own[role.slot()] {
                    Some(c) => format!("the chart {}", c.describe()),
                    None if self.counts[role] > 0 => {
                        format!("{} records held out of it at random", self.counts[role])
                    }
                    None => "none".into(),
                };
                let described = format!(
                    "{} (calibration: {}; validation: {})",
                    chart.describe(),
                    source(ChartRole::Calibration),
                    source(ChartRole::Validation)
                );
                RecordsOrigin::Chart(&described).line()
            }
        }
    }
}

/// A chart's records compressed, split by `roles` (all training without
/// them) into the three role slots, in the file's order; records that
/// cannot be compressed are counted as failures of their role.
fn chart_parts(
    spec: &ModelSpec,
    compressor: &CompressorConfig,
    chart: &ChartFiles,
    roles: Option<&[ChartRole]>,
) -> Result<Vec<CompressedChart>> {
    use twostage_compress::Compressor;
    let (q, n) = (spec.n_params(), compressor.n_features());
    // Features by the chart's row, so that the order of its files never
    // changes the estimator.
    let mut features = vec![f64::NAN; chart.len() * n];
    let mut errors: Vec<Option<String>> = vec![None; chart.len()];
    let mut work = Workspace::new();
    // Each row's inputs' summary numbers, for its role's input family.
    let family = InputFamily::new(spec.input_names().len(), spec.sample_time());
    let mut summaries = vec![Vec::new(); chart.len()];
    chart.for_each_record(spec, |row, record| {
        let alpha = &mut features[row * n..(row + 1) * n];
        if let Err(e) =
            compressor.compress_into(record.inputs(), record.outputs(), &mut work, alpha)
        {
            errors[row] = Some(e.to_string());
        }
        summaries[row] = family.summaries(record);
        Ok(())
    })?;
    let role_of = |row: usize| roles.map_or(ChartRole::Training, |r| r[row]);
    let mut out = Vec::with_capacity(ChartRole::ALL.len());
    for role in ChartRole::ALL {
        let in_part = |row: &usize| role_of(*row) == role;
        let kept: Vec<usize> = (0..chart.len())
            .filter(|row| in_part(row) && errors[*row].is_none())
            .collect();
        let failures = (0..chart.len())
            .filter(in_part)
            .filter_map(|row| {
                errors[row].as_ref().map(|e| ExperimentFailure {
                    index: row,
                    theta: chart.theta(row).to_vec(),
                    error: e.clone(),
                })
            })
            .collect();
        let thetas: Vec<f64> = kept
            .iter()
            .flat_map(|&r| chart.theta(r).iter().copied())
            .collect();
        let kept_features: Vec<f64> = kept
            .iter()
            .flat_map(|&r| features[r * n..(r + 1) * n].iter().copied())
            .collect();
        let rows = kept.len();
        let shape = |v: Vec<f64>, w: usize| {
            ndarray::Array2::from_shape_vec((rows, w), v)
                .unwrap_or_else(|_| unreachable!("rows * width values were kept"))
        };
        let mut inputs = family.clone();
        for &r in &kept {
            inputs.include_summaries(&summaries[r]);
        }
        out.push(CompressedChart {
            thetas: shape(thetas, q),
            features: shape(kept_features, n),
            indices: kept,
            failures,
            inputs: Some(inputs),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::Silent;
    use twostage_models::Benchmark;

    fn records<'a>(model: &'a Benchmark, sampling: Sampling, m: usize) -> Records<'a, Benchmark> {
        Records::open(
            model,
            RecordSource::Simulated,
            RunShape {
                training_prior: model.spec().prior().clone().with_sampling(sampling),
                counts: RoleCounts::new(m, 0, 0),
                seed: 11,
                max_failure_fraction: 0.0,
                progress: &Silent,
            },
        )
        .unwrap()
    }

    /// Grown by `more_training`, a chart is the very chart a run of the
    /// larger count stores, where the sampling allows; a Latin hypercube
    /// does not grow.
    #[test]
    fn more_training_extends_the_chart_a_larger_run_stores() {
        let model = Benchmark::builder().n_samples(40).build().unwrap();
        for sampling in [Sampling::Uniform, Sampling::Sobol] {
            let (small, _) = records(&model, sampling, 30).stored_training().unwrap();
            let (more, failed) = records(&model, sampling, 30)
                .more_training(30, 75)
                .unwrap()
                .unwrap();
            assert_eq!((more.records.len(), failed), (45, 0));
            let (whole, _) = records(&model, sampling, 75).stored_training().unwrap();
            let grown: Vec<&IoData> = small.records.iter().chain(&more.records).collect();
            assert!(grown.iter().zip(&whole.records).all(|(a, b)| *a == b));
            assert_eq!(more.thetas, whole.thetas.slice(ndarray::s![30.., ..]));
        }
        let lhs = records(&model, Sampling::LatinHypercube, 30);
        assert!(!lhs.can_grow());
        assert!(lhs.more_training(30, 75).unwrap().is_none());
    }
}
