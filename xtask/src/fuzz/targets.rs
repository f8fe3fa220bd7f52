//! The readers fuzzed: what each reads, how its corpus is sealed, and what
//! one execution does with an input (read it, and use what reads).

use std::path::{Path, PathBuf};

use twostage::models::{ExternalSimulator, IoData, Simulator, run_experiment};
use twostage::sources::{ModelFile, ModelSource, csv_rows};

mod on_disk;

pub(crate) use on_disk::{NPY_FILES, npy_chart, scratch_root, shard_sets};

/// A reader of outside data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Reader {
    /// Estimator files (`Estimator::from_bytes`), then an estimate.
    EstimatorFile,
    /// The embedded runtime's blobs, then a record streamed through them
    /// (and drawn from, where a blob carries a posterior).
    RuntimeBlob,
    /// Model files (`ModelFile::parse`): built-in sources and equations
    /// are built and simulate one short record; commands never run.
    ModelFile,
    /// CSV rows (`csv_rows::for_each_row`, under records and charts).
    CsvRows,
    /// NumPy charts (`ChartFiles::open`, every record read): one of
    /// theta.npy, inputs.npy and outputs.npy, the others valid.
    NpyChart,
    /// Shard files (`ShardedChart::open`, then training on them): one of
    /// two shards, the other valid.
    ShardFile,
    /// A simulator's answer to one experiment, line by line
    /// (`ExternalSimulator::read_answer`).
    ProtocolAnswer,
    /// An FMU's `modelDescription.xml` (`ModelDescription::parse`).
    FmuDescription,
    /// FMU archives (`Fmu::open`: unpacked, described, never loaded).
    FmuArchive,
}

impl Reader {
    /// Every reader, in the order a run of all of them takes.
    pub(crate) const ALL: [Self; 9] = [
        Self::EstimatorFile,
        Self::RuntimeBlob,
        Self::ModelFile,
        Self::CsvRows,
        Self::NpyChart,
        Self::ShardFile,
        Self::ProtocolAnswer,
        Self::FmuDescription,
        Self::FmuArchive,
    ];

    /// The name on the command line and of the corpus folder.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::EstimatorFile => "estimator-file",
            Self::RuntimeBlob => "runtime-blob",
            Self::ModelFile => "model-file",
            Self::CsvRows => "csv-rows",
            Self::NpyChart => "npy-chart",
            Self::ShardFile => "shard-file",
            Self::ProtocolAnswer => "protocol-answer",
            Self::FmuDescription => "fmu-description",
            Self::FmuArchive => "fmu-archive",
        }
    }

    /// Where its corpus is kept.
    pub(crate) fn corpus_dir(self) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fuzz")
            .join(self.name())
    }

    /// Whether it reads text (tokens are swapped whole).
    pub(crate) fn reads_text(self) -> bool {
        matches!(
            self,
            Self::ModelFile | Self::CsvRows | Self::ProtocolAnswer | Self::FmuDescription
        )
    }

    /// Set a binary input's length and checksum to its bytes, so that a
    /// mutation reaches the checks behind the checksum.
    pub(crate) fn seal(self, input: &mut [u8]) {
        match self {
            Self::EstimatorFile => seal_estimator_file(input),
            Self::RuntimeBlob => seal_runtime_blob(input),
            Self::ShardFile => on_disk::seal_shard(input),
            Self::ModelFile
            | Self::CsvRows
            | Self::NpyChart
            | Self::ProtocolAnswer
            | Self::FmuDescription
            | Self::FmuArchive => {}
        }
    }

    /// One execution: read `input` and use whatever reads; whether the
    /// reader accepted it. Errors are the reader doing its job; only a
    /// panic, an abort or endless work is a finding.
    pub(crate) fn exercise(self, input: &[u8]) -> bool {
        match self {
            Self::EstimatorFile => estimator_file(input),
            Self::RuntimeBlob => runtime_blob(input),
            Self::ModelFile => model_file(input),
            Self::CsvRows => csv(input),
            Self::NpyChart => on_disk::npy(input),
            Self::ShardFile => on_disk::shards(input),
            Self::ProtocolAnswer => protocol_answer(input),
            Self::FmuDescription => fmu_description(input),
            Self::FmuArchive => on_disk::fmu_archive(input),
        }
    }
}

/// Records longer than this are not estimated: the work would be the
/// record's, not the reader's.
const LONGEST_RECORD: usize = 20_000;

/// Model files' records longer than this are not simulated: with up to
/// 100,000 integrator steps a sample, a longer one is seconds of honest
/// work, which the fuzzer would count as endless.
const LONGEST_SIMULATION: usize = 2_000;

/// A record of the given shape, a few sines.
fn record(samples: usize, inputs: usize, outputs: usize) -> IoData {
    let mut record = IoData::zeros(samples, inputs, outputs);
    for j in 0..inputs {
        for (k, u) in record.input_mut(j).iter_mut().enumerate() {
            *u = (0.1 * k as f64 + j as f64).sin();
        }
    }
    for j in 0..outputs {
        for (k, y) in record.output_mut(j).iter_mut().enumerate() {
            *y = (0.07 * k as f64 - j as f64).cos();
        }
    }
    record
}

fn seal_estimator_file(input: &mut [u8]) {
    // The header: magic (8), version (4), payload length (8), CRC-32 (4).
    let Some((header, payload)) = input.split_at_mut_checked(24) else {
        return;
    };
    header[12..20].copy_from_slice(&(payload.len() as u64).to_le_bytes());
    header[20..24].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
}

fn seal_runtime_blob(input: &mut [u8]) {
    use twostage::runtime::format::{CHECKSUM_FROM, HEADER_BYTES, checksum};
    if input.len() < HEADER_BYTES {
        return;
    }
    let Ok(length) = u32::try_from(input.len()) else {
        return;
    };
    input[8..12].copy_from_slice(&length.to_le_bytes());
    let crc = checksum(&input[CHECKSUM_FROM..]);
    input[12..16].copy_from_slice(&crc.to_le_bytes());
}

fn estimator_file(input: &[u8]) -> bool {
    let Ok(estimator) = twostage::Estimator::from_bytes(input) else {
        return false;
    };
    let _ = estimator.to_bytes();
    let shape = estimator.record_shape();
    if shape.n_samples <= LONGEST_RECORD {
        let _ =
            estimator.estimate_record(&record(shape.n_samples, shape.n_inputs, shape.n_outputs));
    }
    true
}

fn runtime_blob(input: &[u8]) -> bool {
    use twostage::runtime::{Estimator, Stream};
    let Ok(estimator) = Estimator::from_bytes(input) else {
        return false;
    };
    let mut work = vec![0.0; estimator.workspace_len().min(1 << 20)];
    let q = estimator.n_parameters();
    let (mut theta, mut widths) = (vec![0.0; q], vec![0.0; q]);
    let samples = estimator.trained_samples().min(LONGEST_RECORD);
    let data = record(samples, estimator.n_inputs(), estimator.n_outputs());
    let Ok(mut stream) = Stream::new(&estimator, &mut work) else {
        return true;
    };
    let (mut u, mut y) = (vec![0.0; data.n_inputs()], vec![0.0; data.n_outputs()]);
    for k in 0..samples {
        for (j, value) in u.iter_mut().enumerate() {
            *value = data.input(j)[k];
        }
        for (j, value) in y.iter_mut().enumerate() {
            *value = data.output(j)[k];
        }
        let _ = stream.push(&u, &y);
    }
    if let Ok(answer) = stream.finish(&mut theta, &mut widths) {
        let _ = answer.out_of_distribution();
    }
    if estimator.has_posterior() {
        let mut draws = vec![0.0; 8 * q];
        let _ = stream.finish_with_draws(&mut theta, &mut widths, &mut draws, 1, 0);
    }
    true
}

fn model_file(input: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(input) else {
        return false;
    };
    let Ok(file) = ModelFile::parse(text, "fuzz.toml") else {
        return false;
    };
    // A command is a program to run and an FMU a file to open: never here.
    if !matches!(
        file.source(),
        ModelSource::Builtin { .. } | ModelSource::Equations { .. }
    ) {
        return true;
    }
    let Ok(simulator) = file.simulator() else {
        return true;
    };
    let spec = simulator.spec();
    if spec.n_samples() > LONGEST_SIMULATION {
        return true;
    }
    let Ok(design) = simulator.prior().design(1, 7) else {
        return true;
    };
    let mut theta = vec![0.0; simulator.prior().dim()];
    let mut record = spec.new_record();
    let _ = run_experiment(simulator.as_ref(), &design, 0, &mut theta, &mut record);
    true
}

fn csv(input: &[u8]) -> bool {
    csv_rows::for_each_row(
        input,
        |_, row| {
            let _: Vec<Result<f64, _>> = row.iter().map(str::parse::<f64>).collect();
            Ok::<(), String>(())
        },
        |line, message| format!("{line:?}: {message}"),
    )
    .is_ok()
}

/// Samples of the record a protocol answer is read into (one input, one
/// output): the corpus's answers have this many.
pub(crate) const ANSWER_SAMPLES: usize = 50;

fn protocol_answer(input: &[u8]) -> bool {
    let text = String::from_utf8_lossy(input);
    let mut lines = text
        .split('\n')
        .map(|line| line.trim_end_matches('\r').to_string());
    let mut next_line = || lines.next().ok_or_else(|| "it ended".to_string());
    let mut out = IoData::zeros(ANSWER_SAMPLES, 1, 1);
    // A failure said in protocol is an answer read, as a record is.
    ExternalSimulator::read_answer(&mut next_line, 0, &mut out).is_ok()
}

fn fmu_description(input: &[u8]) -> bool {
    use twostage::fmi::{InterfaceKind, ModelDescription};
    let Ok(text) = std::str::from_utf8(input) else {
        return false;
    };
    let Ok(description) = ModelDescription::parse(text, "fuzz.fmu") else {
        return false;
    };
    let _ = description.similar_names("u");
    let _ = description.interface(InterfaceKind::CoSimulation);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_changed_payload_resealed_passes_the_checksum_and_unsealed_does_not() {
        for reader in [Reader::EstimatorFile, Reader::RuntimeBlob] {
            for entry in super::super::run::corpus(reader).unwrap() {
                let mut changed = entry.clone();
                let last = changed.len() - 1;
                changed[last] ^= 0x5a;
                let checksum_error = |bytes: &[u8]| match reader {
                    Reader::EstimatorFile => twostage::Estimator::from_bytes(bytes)
                        .err()
                        .is_some_and(|e| e.to_string().contains("checksum")),
                    _ => matches!(
                        twostage::runtime::Estimator::from_bytes(bytes),
                        Err(twostage::runtime::Error::Checksum { .. })
                    ),
                };
                assert!(checksum_error(&changed), "{}", reader.name());
                reader.seal(&mut changed);
                assert!(!checksum_error(&changed), "{}", reader.name());
                let mut same = entry.clone();
                reader.seal(&mut same);
                assert_eq!(same, entry, "sealing a whole file changes nothing");
            }
        }
    }
}
