//! The readers that read files from a folder: NumPy charts, shard sets
//! and FMU archives. One input is one file of a valid set (its first byte
//! says which); the rest of the set is written beside it as made here, so
//! that a mutation reaches the reader through a set that is otherwise
//! whole. Each child writes into a folder of its own.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use twostage::models::{Benchmark, Simulator};
use twostage::sources::{ChartFiles, RoleCounts, ShardIndex, ShardPlan, ShardedChart};
use twostage::{RecordSource, TwoStage, simulate_shard};

/// Samples of every record of these sets: small, so that an execution is
/// the reader's work.
const SAMPLES: usize = 40;

/// The model every set is of.
fn model() -> &'static Benchmark {
    static MODEL: OnceLock<Benchmark> = OnceLock::new();
    MODEL.get_or_init(|| {
        Benchmark::builder()
            .n_samples(SAMPLES)
            .build()
            .unwrap_or_else(|e| unreachable!("a benchmark of {SAMPLES} samples builds: {e}"))
    })
}

/// The folder under which each child writes (a folder of its own, made
/// once; each execution writes the same names over the last's), removed
/// by the run when a reader is done.
pub(crate) fn scratch_root() -> PathBuf {
    crate::target_dir().join("fuzz").join("scratch")
}

fn scratch() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch_root().join(std::process::id().to_string());
        let _ = std::fs::create_dir_all(&dir);
        dir
    })
}

/// The NumPy chart's files, in the order an input's first byte picks
/// them: theta [3, 1], inputs and outputs [3, N, 1].
pub(crate) const NPY_FILES: [&str; 3] = ["theta.npy", "inputs.npy", "outputs.npy"];

/// A float64 .npy file of `shape`.
fn npy_bytes(shape: &[u64], values: &[f64]) -> Vec<u8> {
    use npyz::WriterBuilder;
    let mut bytes = std::io::Cursor::new(Vec::new());
    if let Ok(mut writer) = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut bytes)
        .begin_nd()
    {
        let _ = writer.extend(values.iter().copied());
        let _ = writer.finish();
    }
    bytes.into_inner()
}

/// A valid NumPy chart of three records, [`NPY_FILES`]' bytes.
pub(crate) fn npy_chart() -> &'static [Vec<u8>; 3] {
    static FILES: OnceLock<[Vec<u8>; 3]> = OnceLock::new();
    FILES.get_or_init(|| {
        let thetas = [0.3, -0.2, 0.7];
        let (mut inputs, mut outputs) = (Vec::new(), Vec::new());
        for (r, theta) in thetas.iter().enumerate() {
            let mut record = model().spec().new_record();
            let mut rng = twostage::models::experiment_rng(11, r as u64);
            let _ = model().simulate(&[*theta], &mut rng, &mut record);
            inputs.extend_from_slice(record.input(0));
            outputs.extend_from_slice(record.output(0));
        }
        let m = thetas.len() as u64;
        [
            npy_bytes(&[m, 1], &thetas),
            npy_bytes(&[m, SAMPLES as u64, 1], &inputs),
            npy_bytes(&[m, SAMPLES as u64, 1], &outputs),
        ]
    })
}

/// One input of the NumPy chart reader: file `input[0] % 3` replaced by
/// the rest; the chart opened and every record read.
pub(super) fn npy(input: &[u8]) -> bool {
    let Some((&which, bytes)) = input.split_first() else {
        return false;
    };
    let dir = scratch().join("npy");
    let _ = std::fs::create_dir_all(&dir);
    let which = usize::from(which) % NPY_FILES.len();
    for (k, (name, valid)) in NPY_FILES.iter().zip(npy_chart()).enumerate() {
        let _ = std::fs::write(dir.join(name), if k == which { bytes } else { valid });
    }
    let spec = model().spec();
    let Ok(chart) = ChartFiles::open(&dir, spec) else {
        return false;
    };
    chart.for_each_record(spec, |_, _| Ok(())).is_ok()
}

/// Records of the sharded chart: small, so one execution trains on all.
const SHARD_COUNTS: RoleCounts = RoleCounts {
    training: 30,
    calibration: 0,
    validation: 8,
};

/// The stage 1 of the compressed shard set and of every training here.
const SHARD_COMPRESSOR: &str = "arx:1,1";

/// Two valid shard sets of two shards each: raw records (`[0]`) and
/// compressed ones (`[1]`), each shard's file bytes.
pub(crate) fn shard_sets() -> &'static [[Vec<u8>; 2]; 2] {
    static SETS: OnceLock<[[Vec<u8>; 2]; 2]> = OnceLock::new();
    SETS.get_or_init(|| {
        let set = |compressor: Option<&str>| -> [Vec<u8>; 2] {
            let plan = ShardPlan {
                model: "benchmark".into(),
                model_fingerprint: 17,
                seed: 4,
                counts: SHARD_COUNTS,
                compressor: compressor.map(str::to_string),
            };
            let dir = scratch().join(format!("made-{}", compressor.is_some()));
            [0, 1].map(|index| {
                simulate_shard(model(), &plan, ShardIndex { index, count: 2 }, &dir)
                    .ok()
                    .and_then(|path| std::fs::read(path).ok())
                    .unwrap_or_default()
            })
        };
        [set(None), set(Some(SHARD_COMPRESSOR))]
    })
}

/// One input of the shard reader: its first byte's bit 0 picks the shard
/// it stands for, bit 1 the set (raw or compressed) of the other shard;
/// the set opened and an estimator trained on it.
pub(super) fn shards(input: &[u8]) -> bool {
    let Some((&which, bytes)) = input.split_first() else {
        return false;
    };
    let (slot, set) = (usize::from(which & 1), usize::from((which >> 1) & 1));
    let dir = scratch().join("shards");
    let _ = std::fs::create_dir_all(&dir);
    for (k, valid) in shard_sets()[set].iter().enumerate() {
        let name = format!("shard-{k:05}-of-00002.tsshard");
        let _ = std::fs::write(dir.join(name), if k == slot { bytes } else { valid });
    }
    let Ok(chart) = ShardedChart::open(&format!("{}/shard-*", dir.display())) else {
        return false;
    };
    let Ok(compressor) = SHARD_COMPRESSOR.parse::<twostage::CompressorConfig>() else {
        return false;
    };
    let Ok(regressor) = "linear".parse::<twostage::RegressorConfig>() else {
        return false;
    };
    TwoStage::builder(model())
        .compressor(compressor)
        .regressor(regressor)
        .simulations(SHARD_COUNTS.training)
        .calibration(SHARD_COUNTS.calibration)
        .validation(SHARD_COUNTS.validation)
        .seed(4)
        .records(RecordSource::Shards(&chart))
        .train()
        .is_ok()
}

/// A shard's checksum, past its selector byte: CRC-32 of all between the
/// magic and the last four bytes.
pub(super) fn seal_shard(input: &mut [u8]) {
    let Some(file) = input.get_mut(1..) else {
        return;
    };
    if file.len() < 12 {
        return;
    }
    let end = file.len() - 4;
    let crc = crc32fast::hash(&file[8..end]);
    file[end..].copy_from_slice(&crc.to_le_bytes());
}

/// One input of the FMU reader: the archive opened (unpacked, its
/// description read, the binary for this platform looked for, never
/// loaded: an FMU's binary is code, not data).
pub(super) fn fmu_archive(input: &[u8]) -> bool {
    let path = scratch().join("fuzz.fmu");
    if std::fs::write(&path, input).is_err() {
        return false;
    }
    let Ok(fmu) = twostage::fmi::Fmu::open(&path) else {
        return false;
    };
    let _ = fmu.binary_here();
    !fmu.description().variables.is_empty()
}
