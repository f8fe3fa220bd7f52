//! Running the fuzzer: inputs made from (seed, index), run in child
//! processes chunk by chunk, findings narrowed down to their input.

use std::fs;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use arbitrary::Unstructured;
use rand::Rng;
use twostage::models::experiment_rng;

use super::Reader;
use super::mutate::mutate;

/// Random bytes that decide one input's mutations.
const NOISE_BYTES: usize = 512;

/// Out of how many inputs of a sealed format one is left as mutated (its
/// checksum then fails, as a corrupted download's would).
const UNSEALED_ONE_IN: u64 = 10;

/// The address space a child may take: an input that makes a reader ask
/// for more aborts it, and is reported.
const CHILD_ADDRESS_SPACE: u64 = 4 << 30;

/// A chunk is given this many times its expected seconds (and at least
/// [`LEAST_CHUNK_SECONDS`]) before it counts as endless work.
const CHUNK_TIME_FACTOR: f64 = 20.0;
const LEAST_CHUNK_SECONDS: f64 = 30.0;

/// Chunks are sized to take about this long once the first is timed:
/// long enough that starting a child costs little, short enough that a
/// death is narrowed down quickly.
const AIMED_CHUNK_SECONDS: f64 = 2.0;

/// A reader's corpus: its files' bytes, in file-name order.
pub(crate) fn corpus(reader: Reader) -> Result<Vec<Vec<u8>>> {
    let dir = reader.corpus_dir();
    let mut paths: Vec<PathBuf> = fs::read_dir(&dir)
        .with_context(|| format!("reading the corpus {}", dir.display()))?
        .map(|entry| entry.map(|e| e.path()))
        .collect::<std::io::Result<_>>()?;
    paths.sort();
    let corpus: Vec<Vec<u8>> = paths.iter().map(fs::read).collect::<std::io::Result<_>>()?;
    if corpus.is_empty() {
        bail!(
            "the corpus {} is empty: cargo xtask fuzz --write-corpus fills it",
            dir.display()
        );
    }
    Ok(corpus)
}

/// Input `index` of run `seed`: a corpus entry mutated as the index's own
/// random stream decides.
pub(crate) fn input(reader: Reader, corpus: &[Vec<u8>], seed: u64, index: u64) -> Vec<u8> {
    let mut rng = experiment_rng(seed, index);
    let mut noise = [0u8; NOISE_BYTES];
    rng.fill_bytes(&mut noise);
    let pick = |word: u64| {
        corpus
            .get((word % corpus.len() as u64) as usize)
            .cloned()
            .unwrap_or_default()
    };
    let mut input = pick(rng.next_u64());
    let other = pick(rng.next_u64());
    // Running out of noise ends the mutations early: still an input.
    let _ = mutate(
        &mut Unstructured::new(&noise),
        &mut input,
        &other,
        reader.reads_text(),
    );
    if !rng.next_u64().is_multiple_of(UNSEALED_ONE_IN) {
        reader.seal(&mut input);
    }
    input
}

/// What one input did that a reader must never do.
#[derive(Debug, Clone)]
pub(crate) struct Finding {
    pub index: u64,
    pub what: String,
}

/// In a child: run inputs `from..from + count`, each panic caught and
/// printed as `panic <index> <message>`, then `done <accepted>` (how many
/// the reader accepted).
pub(crate) fn chunk(reader: Reader, seed: u64, from: u64, count: u64) -> Result<()> {
    limit_address_space()?;
    let corpus = corpus(reader)?;
    // The panics are reported by index; the default hook would print each.
    std::panic::set_hook(Box::new(|_| {}));
    let mut out = std::io::stdout().lock();
    let mut accepted = 0u64;
    for index in from..from + count {
        let bytes = input(reader, &corpus, seed, index);
        match std::panic::catch_unwind(|| reader.exercise(&bytes)) {
            Ok(read) => accepted += u64::from(read),
            Err(payload) => {
                let message = payload
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_string())
                    .or_else(|| payload.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                writeln!(out, "panic {index} {}", message.replace('\n', " "))?;
            }
        }
    }
    writeln!(out, "done {accepted}")?;
    Ok(())
}

fn limit_address_space() -> Result<()> {
    use rustix::process::{Resource, Rlimit, setrlimit};
    let limit = Rlimit {
        current: Some(CHILD_ADDRESS_SPACE),
        maximum: Some(CHILD_ADDRESS_SPACE),
    };
    setrlimit(Resource::As, limit).context("limiting the child's address space")
}

/// How a child's chunk ended.
enum Ended {
    /// It printed `done`: how many inputs the reader accepted, and these
    /// panics, if any.
    Done(u64, Vec<Finding>),
    /// It died or ran out of time (said how).
    Died(String),
}

fn run_child(reader: Reader, seed: u64, from: u64, count: u64, allowed: Duration) -> Result<Ended> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(["fuzz-chunk", "--reader", reader.name(), "--seed"])
        .arg(seed.to_string())
        .arg("--from")
        .arg(from.to_string())
        .arg("--count")
        .arg(count.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .context("starting a fuzzing child")?;
    let stdout = child.stdout.take().context("the child's output")?;
    let reading = std::thread::spawn(move || -> Vec<String> {
        BufReader::new(stdout)
            .lines()
            .map_while(std::result::Result::ok)
            .collect()
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break Some(status);
        }
        if start.elapsed() > allowed {
            child.kill()?;
            child.wait()?;
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let lines = reading.join().unwrap_or_default();
    match status {
        None => Ok(Ended::Died(format!(
            "still running after {:.0} s",
            allowed.as_secs_f64()
        ))),
        Some(status)
            if status.success() && lines.last().is_some_and(|l| l.starts_with("done ")) =>
        {
            let accepted = lines
                .last()
                .and_then(|l| l.strip_prefix("done "))
                .and_then(|n| n.parse().ok())
                .unwrap_or(0);
            let findings = lines
                .iter()
                .filter_map(|line| {
                    let rest = line.strip_prefix("panic ")?;
                    let (index, message) = rest.split_once(' ').unwrap_or((rest, ""));
                    Some(Finding {
                        index: index.parse().ok()?,
                        what: format!("panicked: {message}"),
                    })
                })
                .collect();
            Ok(Ended::Done(accepted, findings))
        }
        Some(status) => Ok(Ended::Died(format!("the process ended: {status}"))),
    }
}

/// Run `from..from + count`: how many the reader accepted, and what was
/// found, a death narrowed down to its inputs by running halves again (the
/// inputs are the same every time).
fn run_range(
    reader: Reader,
    seed: u64,
    from: u64,
    count: u64,
    allowed: Duration,
) -> Result<(u64, Vec<Finding>)> {
    match run_child(reader, seed, from, count, allowed)? {
        Ended::Done(accepted, findings) => Ok((accepted, findings)),
        Ended::Died(what) if count == 1 => Ok((0, vec![Finding { index: from, what }])),
        Ended::Died(_) => {
            let half = count / 2;
            let (a, mut findings) = run_range(reader, seed, from, half, allowed)?;
            let (b, more) = run_range(reader, seed, from + half, count - half, allowed)?;
            findings.extend(more);
            Ok((a + b, findings))
        }
    }
}

/// How long a run goes on.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Length {
    /// This many inputs (reproducible: CI's).
    Executions(u64),
    /// Chunks start until this much time has passed.
    Seconds(f64),
}

/// What a run of one reader did.
pub(crate) struct Summary {
    pub executions: u64,
    /// Inputs the reader accepted (read without an error).
    pub accepted: u64,
    pub seconds: f64,
    pub findings: Vec<Finding>,
}

/// Fuzz `reader` from input 0 of `seed` on `jobs` children at a time.
pub(crate) fn fuzz(reader: Reader, seed: u64, length: Length, jobs: usize) -> Result<Summary> {
    corpus(reader)?;
    let start = Instant::now();
    let next = AtomicU64::new(0);
    let done = AtomicU64::new(0);
    let accepted = AtomicU64::new(0);
    let findings = Mutex::new(Vec::new());
    // Chunks are sized to a few seconds once the first has been timed.
    let chunk_size = AtomicU64::new(500);
    let worker = || -> Result<()> {
        loop {
            let size = chunk_size.load(Ordering::Relaxed);
            let from = next.fetch_add(size, Ordering::Relaxed);
            let count = match length {
                Length::Executions(total) if from >= total => return Ok(()),
                Length::Executions(total) => size.min(total - from),
                Length::Seconds(seconds) if start.elapsed().as_secs_f64() >= seconds => {
                    return Ok(());
                }
                Length::Seconds(_) => size,
            };
            let began = Instant::now();
            let allowed = Duration::from_secs_f64(
                LEAST_CHUNK_SECONDS.max(CHUNK_TIME_FACTOR * AIMED_CHUNK_SECONDS),
            );
            let (read, found) = run_range(reader, seed, from, count, allowed)?;
            accepted.fetch_add(read, Ordering::Relaxed);
            let took = began.elapsed().as_secs_f64().max(1e-3);
            let aimed =
                ((count as f64) * AIMED_CHUNK_SECONDS / took).clamp(100.0, 1_000_000.0) as u64;
            chunk_size.store(aimed, Ordering::Relaxed);
            done.fetch_add(count, Ordering::Relaxed);
            findings
                .lock()
                .map_err(|_| anyhow::anyhow!("a worker panicked"))?
                .extend(found);
        }
    };
    std::thread::scope(|scope| -> Result<()> {
        let handles: Vec<_> = (0..jobs.max(1)).map(|_| scope.spawn(worker)).collect();
        for handle in handles {
            handle
                .join()
                .map_err(|_| anyhow::anyhow!("a fuzzing worker panicked"))??;
        }
        Ok(())
    })?;
    let mut findings = findings
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a worker panicked"))?;
    findings.sort_by_key(|f| f.index);
    Ok(Summary {
        executions: done.load(Ordering::Relaxed),
        accepted: accepted.load(Ordering::Relaxed),
        seconds: start.elapsed().as_secs_f64(),
        findings,
    })
}

/// Keep each finding's input where a test can be made of it.
pub(crate) fn keep_findings(
    reader: Reader,
    seed: u64,
    findings: &[Finding],
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let corpus = corpus(reader)?;
    let dir = dir.join(reader.name());
    fs::create_dir_all(&dir)?;
    findings
        .iter()
        .map(|finding| {
            let path = dir.join(format!("seed-{seed}-input-{}.bin", finding.index));
            fs::write(&path, input(reader, &corpus, seed, finding.index))?;
            Ok(path)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_depends_on_its_seed_and_index_alone() {
        let corpus = vec![b"a = 1\n[b]\nc = [2, 3]\n".to_vec(), b"x,y\n1,2\n".to_vec()];
        let make = |seed, index| input(Reader::CsvRows, &corpus, seed, index);
        assert_eq!(make(1, 5), make(1, 5));
        let others: Vec<Vec<u8>> = (0..50).map(|i| make(1, i)).collect();
        let distinct: std::collections::BTreeSet<&Vec<u8>> = others.iter().collect();
        assert!(distinct.len() > 40, "{} distinct of 50", distinct.len());
        assert_ne!(make(1, 7), make(2, 7));
    }

    #[test]
    fn every_corpus_file_is_accepted_by_its_reader() {
        for reader in Reader::ALL {
            for (k, entry) in corpus(reader).unwrap().iter().enumerate() {
                // The example model files of a command or an FMU read too:
                // they are only not run.
                assert!(reader.exercise(entry), "{} entry {k}", reader.name());
            }
        }
        let _ = fs::remove_dir_all(super::super::targets::scratch_root());
    }
}
