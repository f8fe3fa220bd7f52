//! Charts simulated in shards, on a cluster, and merged bit for bit.
//!
//! A training run simulates three designs: the training chart, and the
//! calibration and validation charts (i.i.d. uniform, with their own
//! streams). Shard `i` of `n` simulates records `[i m / n, (i + 1) m / n)` of
//! each, exactly as the single-machine run would (experiment `j` of a design
//! depends on the seed and `j` alone), and writes them, raw or already
//! compressed, to one file with a checksum. [`ShardedChart::open`] checks
//! that a set of shard files belongs together and leaves nothing out, and
//! the facade's `train` over [`RecordSource::Shards`](crate::RecordSource::Shards)
//! trains the very estimator the same run trains on simulated records (docs/cluster.md,
//! docs/decisions/023-sharded-charts.md).

use crate::InvalidSetting;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use twostage_compress::{Compressor, Workspace};
use twostage_models::{InputFamily, IoData, RecordShape, Sampling, Simulator};

use crate::chart::ForModel;
use crate::chart::{CompressedChart, ExperimentFailure, StoredChart, simulate_range};
use crate::error::{Error, Result};
use crate::roles::{ChartRole, RoleCounts};
use twostage_compress::CompressorConfig;

mod format;
mod index;

use format::{
    Checksummed, Header, MAGIC, SHARD_FORMAT, Stored, file_name, flatten, read_header, read_part,
    unflatten, write_part,
};
pub use index::ShardIndex;

/// Records simulated (and held in memory) at once while a shard is written.
const BLOCK: usize = 256;
/// A 64-bit FNV-1a hash of `bytes`: identifies a model file in shard
/// headers (a consistency check between shards, not a security measure).
///
/// ```
/// assert_ne!(twostage_sources::fingerprint(b"a = 1"), twostage_sources::fingerprint(b"a = 2"));
/// ```
pub fn fingerprint(bytes: &[u8]) -> u64 {
    // Fowler, Noll and Vo's 64-bit offset basis and prime.
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |hash, &b| {
        (hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// What a sharded chart is: every shard of it must say the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardPlan {
    /// The model's name.
    pub model: String,
    /// Identifies the model's description (a hash of the model file).
    pub model_fingerprint: u64,
    /// The seed of the run.
    pub seed: u64,
    /// Records of the training, calibration and validation charts.
    pub counts: RoleCounts,
    /// The stage-1 compressor the records were compressed with, as the
    /// user wrote it (`arx:2,2`; compared by the configuration it parses
    /// to), or `None` for raw records.
    pub compressor: Option<String>,
}

/// Simulate shard `shard` of the chart `plan` describes with `simulator`
/// and write it into `dir`; returns the file written. Records are
/// compressed when the plan names a compressor (one that needs no
/// preparation: ARX, AR or raw).
///
/// ```
/// use twostage_sources::{RoleCounts, ShardIndex, ShardPlan, ShardedChart, simulate_shard};
/// use twostage_models::{Benchmark, Simulator};
/// let model = Benchmark::builder().n_samples(200).build()?;
/// let plan = ShardPlan {
///     model: "benchmark".into(),
///     model_fingerprint: 7,
///     seed: 3,
///     counts: RoleCounts::new(40, 0, 10),
///     compressor: Some("arx:2,2".into()),
/// };
/// let dir = std::env::temp_dir().join(format!("shards-doc-{}", std::process::id()));
/// for i in 0..2 {
///     simulate_shard(&model, &plan, ShardIndex { index: i, count: 2 }, &dir)?;
/// }
/// let chart = ShardedChart::open(&format!("{}/shard-*", dir.display()))?;
/// assert_eq!(chart.plan().counts, RoleCounts::new(40, 0, 10));
/// # std::fs::remove_dir_all(&dir).ok();
/// # Ok::<(), twostage_sources::Error>(())
/// ```
///
/// # Errors
/// A plan that does not fit the model, a compressor that needs preparing
/// on the whole chart, a failed file write.
pub fn simulate_shard<S: Simulator + ?Sized>(
    simulator: &S,
    plan: &ShardPlan,
    shard: ShardIndex,
    dir: &Path,
) -> Result<PathBuf> {
    let spec = simulator.spec();
    let compressor = plan
        .compressor
        .as_deref()
        .map(|text| -> Result<CompressorConfig> {
            let config: CompressorConfig = text.parse()?;
            let config = config.for_model(spec)?;
            if config.records_to_prepare() > 0 {
                return Err(Error::InvalidSetting(InvalidSetting {
                    name: "compress",
                    value: text.into(),
                    reason: "this compressor is fitted on the first training records of the \
                             whole chart, which one shard does not have: shard raw records \
                             (leave --compress out) and compress when training"
                        .into(),
                }));
            }
            Ok(config)
        })
        .transpose()?;
    let header = Header {
        format: SHARD_FORMAT,
        plan: plan.clone(),
        sampling: spec.prior().sampling(),
        param_names: spec.param_names().to_vec(),
        shape: spec.record_shape(),
        shard: shard.index,
        shards: shard.count,
    };
    std::fs::create_dir_all(dir).map_err(|cause| Error::Io {
        path: dir.display().to_string(),
        cause,
    })?;
    let path = dir.join(file_name(shard));
    // Written to a temporary name and renamed at the end: a killed task
    // leaves no file that looks complete.
    let partial = dir.join(format!("{}.partial", file_name(shard)));
    let io = |cause: std::io::Error| Error::Io {
        path: partial.display().to_string(),
        cause,
    };
    let file = std::fs::File::create(&partial).map_err(io)?;
    let mut out = Checksummed::new(BufWriter::new(file));
    out.inner.write_all(MAGIC).map_err(io)?;
    write_part(&mut out, &header).map_err(io)?;
    for role in ChartRole::ALL {
        let m = plan.counts[role];
        let range = shard.range(m);
        write_part(&mut out, &(range.start as u64, range.end as u64)).map_err(io)?;
        if range.is_empty() {
            continue;
        }
        let design = role.design(spec.prior(), m, plan.seed)?;
        let mut work = Workspace::new();
        let inputs = InputFamily::new(spec.input_names().len(), spec.sample_time());
        for start in range.clone().step_by(BLOCK) {
            let block = start..(start + BLOCK).min(range.end);
            for outcome in simulate_range(simulator, &design, block, None) {
                let stored = stored(outcome, compressor.as_ref(), &inputs, &mut work);
                write_part(&mut out, &stored).map_err(io)?;
            }
        }
    }
    let crc = out.hasher.clone().finalize();
    out.inner.write_all(&crc.to_le_bytes()).map_err(io)?;
    out.inner.flush().map_err(io)?;
    drop(out);
    std::fs::rename(&partial, &path).map_err(|cause| Error::Io {
        path: path.display().to_string(),
        cause,
    })?;
    Ok(path)
}

/// One simulated experiment as a shard stores it: its record, or its
/// features under `compressor` followed by its inputs' summary numbers
/// and shape numbers (`inputs` says how many, shard format 4), or why it
/// failed.
fn stored(
    outcome: std::result::Result<(Vec<f64>, IoData), ExperimentFailure>,
    compressor: Option<&CompressorConfig>,
    inputs: &InputFamily,
    work: &mut Workspace,
) -> Stored {
    let (theta, record) = match outcome {
        Ok(done) => done,
        Err(failure) => {
            return Stored::Failed {
                theta: failure.theta,
                error: failure.error,
            };
        }
    };
    let Some(c) = compressor else {
        return Stored::Kept {
            theta,
            values: flatten(&record),
        };
    };
    let mut alpha = vec![0.0; c.n_features()];
    match c.compress_into(record.inputs(), record.outputs(), work, &mut alpha) {
        Ok(()) => {
            alpha.extend(inputs.summaries(&record));
            Stored::Kept {
                theta,
                values: alpha,
            }
        }
        Err(e) => Stored::Failed {
            theta,
            error: e.to_string(),
        },
    }
}

/// A set of shard files that belong together and cover every record.
#[derive(Debug, Clone)]
pub struct ShardedChart {
    pattern: String,
    /// The files in shard order.
    files: Vec<PathBuf>,
    header: Header,
}

impl ShardedChart {
    /// Find the shard files `pattern` names (a path with `*` and `?`, e.g.
    /// `DIR/shard-*`), read their headers and check that they belong
    /// together (the same model, seed, sizes and structure), that none is
    /// there twice and none is missing.
    ///
    /// # Errors
    /// [`Error::Shards`] naming the file and what differs, or the missing
    /// shards with their record ranges and the command that re-runs them.
    pub fn open(pattern: &str) -> Result<Self> {
        let fail = |message: String| Error::Shards {
            what: pattern.to_string(),
            message,
        };
        let paths = glob::glob(pattern).map_err(|e| fail(format!("not a file pattern: {e}")))?;
        let mut files: Vec<PathBuf> = paths
            .filter_map(std::result::Result::ok)
            .filter(|p| p.is_file() && !p.to_string_lossy().ends_with(".partial"))
            .collect();
        files.sort();
        if files.is_empty() {
            return Err(fail(
                "no shard file matches: simulate them first (twostage simulate --shard I/N \
                 --out DIR, or twostage slurm)"
                    .into(),
            ));
        }
        let mut headers = Vec::with_capacity(files.len());
        for file in &files {
            headers.push(read_header(file)?);
        }
        let first = &headers[0];
        same_chart(&files, &headers)?;
        let by_index = in_shard_order(&headers, &files).map_err(fail)?;
        let files = by_index.into_iter().map(|k| files[k].clone()).collect();
        Ok(Self {
            pattern: pattern.to_string(),
            files,
            header: first.clone(),
        })
    }

    /// What the shards say the chart is.
    pub fn plan(&self) -> &ShardPlan {
        &self.header.plan
    }

    /// The pattern the shards were found by.
    pub fn pattern(&self) -> &str {
        &self.pattern
    }

    /// The shard files, in shard order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The training prior's sampling the shards were drawn with.
    pub fn sampling(&self) -> Sampling {
        self.header.sampling
    }

    /// Check the shards against the model they are trained for.
    ///
    /// # Errors
    /// [`Error::Shards`] when their parameters or record shape differ.
    pub fn check_model(&self, spec: &twostage_models::ModelSpec) -> Result<()> {
        let (held, wanted) = (self.header.shape, spec.record_shape());
        let fail = |message: String| Error::Shards {
            what: self.pattern.clone(),
            message,
        };
        if self.header.param_names != spec.param_names() || held != wanted {
            return Err(fail(format!(
                "the shards hold {} ({}; {} samples of {} inputs and {} outputs every {} s), not \
                 the model {} ({}; {} samples of {} and {} every {} s)",
                self.header.plan.model,
                self.header.param_names.join(", "),
                held.n_samples,
                held.n_inputs,
                held.n_outputs,
                held.sample_time,
                spec.name(),
                spec.param_names().join(", "),
                wanted.n_samples,
                wanted.n_inputs,
                wanted.n_outputs,
                wanted.sample_time
            )));
        }
        Ok(())
    }

    /// The records of `role`, compressed with `compressor` (raw shards) or
    /// as stored (compressed shards), as [`crate::compress_chart`] would
    /// have made them: rows in design order, failures listed.
    pub(crate) fn compressed(
        &self,
        role: ChartRole,
        compressor: &CompressorConfig,
    ) -> Result<CompressedChart> {
        let m = self.header.plan.counts[role];
        let q = self.header.param_names.len();
        let n = compressor.n_features();
        let stored_features = self.header.plan.compressor.is_some();
        let (mut thetas, mut features) = (Vec::with_capacity(m * q), Vec::with_capacity(m * n));
        let (mut indices, mut failures) = (Vec::with_capacity(m), Vec::new());
        let mut work = Workspace::new();
        let RecordShape {
            n_samples: samples,
            n_inputs: n_u,
            n_outputs: n_y,
            ..
        } = self.header.shape;
        let mut record = IoData::zeros(samples, n_u, n_y);
        let mut inputs = InputFamily::new(n_u, self.header.shape.sample_time);
        let summaries = inputs.summary_len();
        self.for_each(role, |index, stored| {
            let (theta, values) = match stored {
                Stored::Failed { theta, error } => {
                    failures.push(ExperimentFailure {
                        index,
                        theta,
                        error,
                    });
                    return Ok(());
                }
                Stored::Kept { theta, values } => (theta, values),
            };
            if stored_features {
                if values.len() != n + summaries {
                    return Err(format!(
                        "{} values, the compressor gives {n} features and the {n_u} input(s) \
                         {summaries} summary numbers",
                        values.len()
                    ));
                }
                thetas.extend_from_slice(&theta);
                features.extend_from_slice(&values[..n]);
                inputs.include_summaries(&values[n..]);
                indices.push(index);
                return Ok(());
            }
            unflatten(&values, &mut record)?;
            let mut alpha = vec![0.0; n];
            match compressor.compress_into(record.inputs(), record.outputs(), &mut work, &mut alpha)
            {
                Ok(()) => {
                    thetas.extend_from_slice(&theta);
                    features.extend_from_slice(&alpha);
                    inputs.include(&record);
                    indices.push(index);
                }
                Err(e) => failures.push(ExperimentFailure {
                    index,
                    theta,
                    error: e.to_string(),
                }),
            }
            Ok(())
        })?;
        let rows = indices.len();
        Ok(CompressedChart {
            thetas: Array2::from_shape_vec((rows, q), thetas)
                .unwrap_or_else(|_| unreachable!("q values per kept record")),
            features: Array2::from_shape_vec((rows, n), features)
                .unwrap_or_else(|_| unreachable!("n values per kept record")),
            indices,
            failures,
            inputs: Some(inputs),
        })
    }

    /// Every kept training record with its parameters (raw shards only),
    /// for an automatic design that compresses them many ways; failed
    /// experiments are listed.
    pub(crate) fn training_records(&self) -> Result<(StoredChart, Vec<ExperimentFailure>)> {
        if let Some(compressor) = &self.header.plan.compressor {
            return Err(Error::Shards {
                what: self.pattern.clone(),
                message: format!(
                    "the shards hold features of {compressor}, the automatic design needs the \
                     records themselves: simulate the shards without --compress, or train with \
                     --compress {compressor} and a --fit"
                ),
            });
        }
        let RecordShape {
            n_samples: samples,
            n_inputs: n_u,
            n_outputs: n_y,
            ..
        } = self.header.shape;
        let q = self.header.param_names.len();
        let (mut thetas, mut records, mut failures) = (Vec::new(), Vec::new(), Vec::new());
        self.for_each(ChartRole::Training, |index, stored| {
            match stored {
                Stored::Kept { theta, values } => {
                    let mut record = IoData::zeros(samples, n_u, n_y);
                    unflatten(&values, &mut record)?;
                    thetas.extend_from_slice(&theta);
                    records.push(record);
                }
                Stored::Failed { theta, error } => failures.push(ExperimentFailure {
                    index,
                    theta,
                    error,
                }),
            }
            Ok(())
        })?;
        let thetas = Array2::from_shape_vec((records.len(), q), thetas)
            .unwrap_or_else(|_| unreachable!("q values per kept record"));
        Ok((StoredChart { thetas, records }, failures))
    }

    /// The first `count` training records that were simulated (raw shards
    /// only), for a compressor fitted on them.
    pub(crate) fn first_training_records(&self, count: usize) -> Result<Vec<IoData>> {
        let RecordShape {
            n_samples: samples,
            n_inputs: n_u,
            n_outputs: n_y,
            ..
        } = self.header.shape;
        let mut records = Vec::with_capacity(count);
        let (mut seen, mut failed) = (0, None);
        self.for_each(ChartRole::Training, |index, stored| {
            if seen == count {
                return Ok(());
            }
            seen += 1;
            match stored {
                Stored::Kept { values, .. } => {
                    let mut record = IoData::zeros(samples, n_u, n_y);
                    unflatten(&values, &mut record)?;
                    records.push(record);
                }
                Stored::Failed { error, .. } => {
                    failed.get_or_insert((index, error));
                }
            }
            Ok(())
        })?;
        match failed {
            // As `train` does: the records a compressor is fitted on must
            // all be there.
            Some((index, error)) => Err(Error::Shards {
                what: self.pattern.clone(),
                message: format!(
                    "training experiment {index}, among the first {count} the compressor is \
                     fitted on, failed: {error}"
                ),
            }),
            None => Ok(records),
        }
    }

    /// Visit the stored experiments of `role` in index order, shard by
    /// shard, verifying each file's checksum.
    fn for_each(
        &self,
        role: ChartRole,
        mut visit: impl FnMut(usize, Stored) -> std::result::Result<(), String>,
    ) -> Result<()> {
        let q = self.header.param_names.len();
        for (i, file) in self.files.iter().enumerate() {
            let fail = |message: String| Error::Shards {
                what: file.display().to_string(),
                message,
            };
            let handle = std::fs::File::open(file).map_err(|e| fail(e.to_string()))?;
            let mut input = Checksummed::new(BufReader::new(handle));
            let mut magic = [0u8; 8];
            input
                .inner
                .read_exact(&mut magic)
                .map_err(|e| fail(e.to_string()))?;
            let _: Header = read_part(&mut input, "the header").map_err(fail)?;
            for r in ChartRole::ALL {
                let (start, end): (u64, u64) = read_part(&mut input, "a range").map_err(fail)?;
                let range = start as usize..end as usize;
                let wanted = r == role;
                let its = ShardIndex {
                    index: i,
                    count: self.header.shards,
                }
                .range(self.header.plan.counts[r]);
                if range != its {
                    return Err(fail(format!(
                        "its {} records are [{start}, {end}), shard {i} of {} should hold [{}, {})",
                        r.label(),
                        self.header.shards,
                        its.start,
                        its.end
                    )));
                }
                for index in range {
                    let stored: Stored = read_part(&mut input, "a record").map_err(fail)?;
                    let (Stored::Kept { theta, .. } | Stored::Failed { theta, .. }) = &stored;
                    if theta.len() != q {
                        return Err(fail(format!(
                            "{} record {index} has {} parameter values, the chart's model has \
                             {q}: the file is damaged",
                            r.label(),
                            theta.len()
                        )));
                    }
                    if wanted {
                        visit(index, stored)
                            .map_err(|e| fail(format!("{} record {index}: {e}", r.label())))?;
                    }
                }
            }
            let computed = input.hasher.clone().finalize();
            let mut stored = [0u8; 4];
            input
                .inner
                .read_exact(&mut stored)
                .map_err(|_| fail("the file ends before its checksum: it was cut short".into()))?;
            if u32::from_le_bytes(stored) != computed {
                return Err(fail(
                    "the checksum does not match: the file is damaged; simulate this shard again"
                        .into(),
                ));
            }
        }
        Ok(())
    }
}

/// Every shard's header says the same chart as the first's.
fn same_chart(files: &[PathBuf], headers: &[Header]) -> Result<()> {
    let first = &headers[0];
    for (file, header) in files.iter().zip(headers).skip(1) {
        let differs = [
            ("model", header.plan.model != first.plan.model),
            (
                "model file",
                header.plan.model_fingerprint != first.plan.model_fingerprint,
            ),
            ("seed", header.plan.seed != first.plan.seed),
            ("chart sizes", header.plan.counts != first.plan.counts),
            (
                "compressor",
                header.plan.compressor != first.plan.compressor,
            ),
            ("sampling", header.sampling != first.sampling),
            ("parameters", header.param_names != first.param_names),
            ("record shape", header.shape != first.shape),
            ("number of shards", header.shards != first.shards),
        ]
        .into_iter()
        .find(|(_, d)| *d);
        if let Some((what, _)) = differs {
            return Err(Error::Shards {
                what: file.display().to_string(),
                message: format!(
                    "its {what} differs from {}'s ({}): shards of different charts are mixed; \
                     keep one chart's shards in a folder",
                    files[0].display(),
                    describe(first)
                ),
            });
        }
    }
    Ok(())
}

/// The index into `files` of each shard, in shard order; a shard there
/// twice or missing is named (with the records a missing one holds and
/// how to re-run it).
fn in_shard_order(
    headers: &[Header],
    files: &[PathBuf],
) -> std::result::Result<Vec<usize>, String> {
    let first = &headers[0];
    let n = first.shards;
    let mut by_index: Vec<Option<usize>> = vec![None; n];
    for (k, header) in headers.iter().enumerate() {
        if let Some(other) = by_index[header.shard] {
            return Err(format!(
                "shard {} of {n} is there twice: {} and {}",
                header.shard,
                files[other].display(),
                files[k].display()
            ));
        }
        by_index[header.shard] = Some(k);
    }
    let missing: Vec<usize> = (0..n).filter(|i| by_index[*i].is_none()).collect();
    if missing.is_empty() {
        return Ok(by_index.into_iter().flatten().collect());
    }
    let ranges: Vec<String> = missing
        .iter()
        .map(|&i| {
            let shard = ShardIndex { index: i, count: n };
            let parts: Vec<String> = ChartRole::ALL
                .into_iter()
                .filter(|&r| first.plan.counts[r] > 0)
                .map(|r| {
                    let range = shard.range(first.plan.counts[r]);
                    format!("{} [{}, {})", r.label(), range.start, range.end)
                })
                .collect();
            format!("shard {i} ({})", parts.join(", "))
        })
        .collect();
    Err(format!(
        "{} of {n} shard(s) missing: {}; re-run them alone (twostage simulate ... \
         --shard I/{n}, or sbatch --array={} on the script twostage slurm wrote)",
        missing.len(),
        ranges.join("; "),
        missing
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(",")
    ))
}

fn describe(header: &Header) -> String {
    format!(
        "model {}, seed {}, {} training, {} calibration and {} validation records, {}, {} shards",
        header.plan.model,
        header.plan.seed,
        header.plan.counts.training,
        header.plan.counts.calibration,
        header.plan.counts.validation,
        header.plan.compressor.as_deref().map_or_else(
            || "raw records".to_string(),
            |c| format!("compressed by {c}")
        ),
        header.shards
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shard whose first training record carries one parameter value
    /// more than the model has, its checksum made to match (as a tool
    /// writing shards wrongly would): refused with the record named, not
    /// a panic (`cargo xtask fuzz --reader shard-file` found it too, seed
    /// 1, input 26111).
    #[test]
    fn a_record_with_another_number_of_parameters_is_named() {
        let model = twostage_models::Benchmark::builder()
            .n_samples(30)
            .build()
            .unwrap();
        let plan = ShardPlan {
            model: "benchmark".into(),
            model_fingerprint: 1,
            seed: 2,
            counts: RoleCounts::new(6, 0, 2),
            compressor: None,
        };
        let dir = std::env::temp_dir().join(format!("shard-theta-{}", std::process::id()));
        let path = simulate_shard(&model, &plan, ShardIndex { index: 0, count: 1 }, &dir).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        // The parts after the magic: the header, then per role its range
        // and its records.
        let mut input = Checksummed::new(&bytes[8..bytes.len() - 4]);
        let mut parts = Vec::new();
        while let Ok(part) = format::read_part_bytes(&mut input, "a part") {
            parts.push(part);
        }
        assert_eq!(
            parts.len(),
            1 + 3 + 8,
            "the header, three ranges, eight records"
        );
        let mut first: Stored = postcard::from_bytes(&parts[2]).unwrap();
        let Stored::Kept { theta, .. } = &mut first else {
            panic!("the first record was simulated");
        };
        theta.push(0.5);
        parts[2] = postcard::to_stdvec(&first).unwrap();
        let mut forged = MAGIC.to_vec();
        let mut hasher = crc32fast::Hasher::new();
        for part in &parts {
            let length = (part.len() as u64).to_le_bytes();
            hasher.update(&length);
            hasher.update(part);
            forged.extend_from_slice(&length);
            forged.extend_from_slice(part);
        }
        forged.extend_from_slice(&hasher.finalize().to_le_bytes());
        std::fs::write(&path, &forged).unwrap();
        let chart = ShardedChart::open(&path.display().to_string()).unwrap();
        let Err(err) = chart.training_records() else {
            panic!("a record of two parameter values was read as the model's one");
        };
        let err = err.to_string();
        assert!(
            err.contains("training record 0 has 2 parameter values, the chart's model has 1"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn fingerprints_are_fnv1a() {
        // The published FNV-1a 64 test vectors.
        assert_eq!(fingerprint(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fingerprint(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fingerprint(b"foobar"), 0x8594_4171_f739_67e8);
    }
}
