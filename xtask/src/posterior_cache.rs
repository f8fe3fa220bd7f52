//! The exact posterior means of a test set, kept between runs: the Bayes
//! reference of 10,000 benchmark records takes minutes and never changes
//! while the records do not. The key is a fingerprint of the records' own
//! numbers (truth, inputs and outputs), so a changed model, seed or
//! steering makes new records and can never meet a stale answer.

use std::fs;
use std::path::{Path, PathBuf};

use twostage::models::IoData;
use twostage::sources::fingerprint;

/// The fingerprint of a test set: every number of its truth and records,
/// bit for bit, in order (each record's fingerprint, then theirs, so that
/// no copy of the whole set is made).
pub(crate) fn key(truth: &[Vec<f64>], records: &[IoData]) -> u64 {
    let mut hashes = Vec::with_capacity(8 * records.len());
    let mut bytes = Vec::new();
    for (theta, record) in truth.iter().zip(records) {
        bytes.clear();
        let inputs = (0..record.n_inputs()).flat_map(|j| record.input(j).iter());
        let outputs = (0..record.n_outputs()).flat_map(|j| record.output(j).iter());
        for x in theta.iter().chain(inputs).chain(outputs) {
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        // Record boundaries count: the same numbers split differently differ.
        bytes.extend_from_slice(&(record.n_samples() as u64).to_le_bytes());
        hashes.extend_from_slice(&fingerprint(&bytes).to_le_bytes());
    }
    fingerprint(&hashes)
}

/// Where the posterior means of the test set `key` are kept.
pub(crate) fn path(dir: &Path, key: u64) -> PathBuf {
    dir.join(format!("posterior-{key:016x}.txt"))
}

/// The kept posterior means of `count` records of `dim` parameters, if a
/// whole and well-formed file is there (anything else is recomputed).
pub(crate) fn load(path: &Path, count: usize, dim: usize) -> Option<Vec<Vec<f64>>> {
    let text = fs::read_to_string(path).ok()?;
    let rows: Vec<Vec<f64>> = text
        .lines()
        .map(|line| {
            line.split(' ')
                .map(|bits| u64::from_str_radix(bits, 16).ok().map(f64::from_bits))
                .collect::<Option<Vec<f64>>>()
        })
        .collect::<Option<_>>()?;
    (rows.len() == count && rows.iter().all(|row| row.len() == dim)).then_some(rows)
}

/// Keep `posterior` at `path`, each number as its bits (exact on reading).
pub(crate) fn store(path: &Path, posterior: &[Vec<f64>]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir)?;
    }
    let text: String = posterior
        .iter()
        .map(|row| {
            let words: Vec<String> = row.iter().map(|x| format!("{:x}", x.to_bits())).collect();
            words.join(" ") + "\n"
        })
        .collect();
    // Written whole, then renamed: an interrupted run leaves no half file.
    let partial = path.with_extension("partial");
    fs::write(&partial, text)?;
    fs::rename(partial, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(y: f64) -> IoData {
        IoData::siso(&[1.0, 2.0], &[y, 0.5]).unwrap()
    }

    #[test]
    fn kept_means_come_back_bit_for_bit() {
        let dir = std::env::temp_dir().join(format!("twostage-posterior-{}", std::process::id()));
        let posterior = vec![vec![0.1, -3.5e-300], vec![f64::MAX, 1.0 / 3.0]];
        let file = path(&dir, 7);
        store(&file, &posterior).unwrap();
        let back = load(&file, 2, 2).unwrap();
        let bits = |rows: &[Vec<f64>]| -> Vec<u64> {
            rows.iter().flatten().map(|x| x.to_bits()).collect()
        };
        assert_eq!(bits(&back), bits(&posterior));
        // The wrong shape is not an answer.
        assert!(load(&file, 3, 2).is_none());
        assert!(load(&file, 2, 1).is_none());
        fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn another_record_or_truth_is_another_key() {
        let base = key(&[vec![0.5]], &[record(0.0)]);
        assert_ne!(base, key(&[vec![0.5]], &[record(1e-12)]));
        assert_ne!(base, key(&[vec![0.25]], &[record(0.0)]));
        assert_eq!(base, key(&[vec![0.5]], &[record(0.0)]));
    }
}
