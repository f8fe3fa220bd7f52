//! The shard file: magic, a postcard header, per chart its range and each
//! record, every part length-prefixed, and a CRC-32 of all after the magic
//! (docs/decisions/023-sharded-charts.md).

use std::io::{BufReader, Read, Write};
use std::path::Path;

use serde::{Deserialize, Serialize};
use twostage_models::{IoData, RecordShape, Sampling};

use super::{ShardIndex, ShardPlan};
use crate::error::{Error, Result};

/// Starts every shard file.
pub(super) const MAGIC: &[u8; 8] = b"TSSHARD\0";
/// The layout of the header and the records; bumped on any change.
/// Format 2 stores the sampling design, the record shape and the
/// compressor as typed values (format 1: as text and a bare triple);
/// format 3 follows a compressed record's features with its inputs'
/// summary numbers (the estimator's input family); format 4 adds their
/// shape numbers after them (the estimator's input shapes).
pub(super) const SHARD_FORMAT: u32 = 4;
/// The header of a shard file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct Header {
    pub(super) format: u32,
    pub(super) plan: ShardPlan,
    /// The training prior's sampling design.
    pub(super) sampling: Sampling,
    pub(super) param_names: Vec<String>,
    pub(super) shape: RecordShape,
    pub(super) shard: usize,
    pub(super) shards: usize,
}

/// One experiment of a shard.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) enum Stored {
    /// Its parameter vector, and its features then its inputs' summary
    /// numbers (compressed shards) or its record's signals, inputs then
    /// outputs, each whole.
    Kept { theta: Vec<f64>, values: Vec<f64> },
    /// Its parameter vector and why it failed.
    Failed { theta: Vec<f64>, error: String },
}

/// The file name of shard `i` of `n`.
pub(super) fn file_name(shard: ShardIndex) -> String {
    format!("shard-{:05}-of-{:05}.tsshard", shard.index, shard.count)
}

/// A record's signals, inputs then outputs, each whole.
pub(super) fn flatten(record: &IoData) -> Vec<f64> {
    let mut values =
        Vec::with_capacity(record.n_samples() * (record.n_inputs() + record.n_outputs()));
    for j in 0..record.n_inputs() {
        values.extend_from_slice(record.input(j));
    }
    for j in 0..record.n_outputs() {
        values.extend_from_slice(record.output(j));
    }
    values
}

/// A writer or reader that checksums what passes through.
pub(super) struct Checksummed<T> {
    pub(super) inner: T,
    pub(super) hasher: crc32fast::Hasher,
}

impl<T> Checksummed<T> {
    pub(super) fn new(inner: T) -> Self {
        Self {
            inner,
            hasher: crc32fast::Hasher::new(),
        }
    }
}

/// One length-prefixed postcard part, checksummed.
pub(super) fn write_part<W: Write, T: Serialize>(
    out: &mut Checksummed<W>,
    value: &T,
) -> std::io::Result<()> {
    let bytes = postcard::to_stdvec(value).map_err(std::io::Error::other)?;
    let length = (bytes.len() as u64).to_le_bytes();
    out.hasher.update(&length);
    out.hasher.update(&bytes);
    out.inner.write_all(&length)?;
    out.inner.write_all(&bytes)
}

/// The largest part a shard file may hold (a record of 2^27 numbers).
pub(super) const MAX_PART: u64 = 1 << 30;

pub(super) fn read_part<R: Read, T: serde::de::DeserializeOwned>(
    input: &mut Checksummed<R>,
    what: &str,
) -> std::result::Result<T, String> {
    let bytes = read_part_bytes(input, what)?;
    postcard::from_bytes(&bytes).map_err(|e| format!("{what} cannot be read ({e})"))
}

/// One length-prefixed part's bytes, checksummed.
pub(super) fn read_part_bytes<R: Read>(
    input: &mut Checksummed<R>,
    what: &str,
) -> std::result::Result<Vec<u8>, String> {
    let mut length = [0u8; 8];
    input
        .inner
        .read_exact(&mut length)
        .map_err(|e| format!("the file ends inside {what} ({e})"))?;
    let n = u64::from_le_bytes(length);
    if n > MAX_PART {
        return Err(format!("{what} claims {n} bytes: the file is damaged"));
    }
    // Grown as the bytes arrive, not taken whole at the length's word: a
    // damaged length is found at the file's end, not by the allocator.
    let mut bytes = Vec::new();
    (&mut input.inner)
        .take(n)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("the file ends inside {what} ({e})"))?;
    if (bytes.len() as u64) < n {
        return Err(format!(
            "the file ends inside {what} ({} of its {n} bytes are there)",
            bytes.len()
        ));
    }
    input.hasher.update(&length);
    input.hasher.update(&bytes);
    Ok(bytes)
}

/// A record's signals back from [`flatten`].
pub(super) fn unflatten(values: &[f64], record: &mut IoData) -> std::result::Result<(), String> {
    let (n, n_u, n_y) = (record.n_samples(), record.n_inputs(), record.n_outputs());
    if values.len() != n * (n_u + n_y) {
        return Err(format!(
            "{} values, a record of {n} samples of {n_u} inputs and {n_y} outputs has {}",
            values.len(),
            n * (n_u + n_y)
        ));
    }
    for j in 0..n_u {
        record
            .input_mut(j)
            .copy_from_slice(&values[j * n..(j + 1) * n]);
    }
    for j in 0..n_y {
        let at = (n_u + j) * n;
        record.output_mut(j).copy_from_slice(&values[at..at + n]);
    }
    Ok(())
}

/// Read and check a shard file's header (not its records).
pub(super) fn read_header(file: &Path) -> Result<Header> {
    let fail = |message: String| Error::Shards {
        what: file.display().to_string(),
        message,
    };
    let handle = std::fs::File::open(file).map_err(|e| fail(e.to_string()))?;
    let mut input = Checksummed::new(BufReader::new(handle));
    let mut magic = [0u8; 8];
    if input.inner.read_exact(&mut magic).is_err() || &magic != MAGIC {
        return Err(fail(
            "not a twostage shard file (written by twostage simulate --shard)".into(),
        ));
    }
    // The format leads the header in every version: read it alone first,
    // so that an older header is named by its format, not misread.
    let bytes = read_part_bytes(&mut input, "the header").map_err(fail)?;
    let format = postcard::take_from_bytes::<u32>(&bytes)
        .map_err(|e| fail(format!("the header is damaged: {e}")))?
        .0;
    if format != SHARD_FORMAT {
        return Err(fail(format!(
            "shard format {format}, this twostage reads {SHARD_FORMAT}: simulate the shards \
             again with this version (twostage simulate --shard, or twostage slurm)"
        )));
    }
    let header: Header =
        postcard::from_bytes(&bytes).map_err(|e| fail(format!("the header is damaged: {e}")))?;
    if header.shards == 0 || header.shard >= header.shards {
        return Err(fail(format!(
            "shard {} of {}: the header is damaged",
            header.shard, header.shards
        )));
    }
    Ok(header)
}
