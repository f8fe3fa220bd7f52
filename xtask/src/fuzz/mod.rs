//! A fuzzer of the readers of outside data, on the stable toolchain.
//!
//! cargo-fuzz needs a nightly compiler, which this project's machines
//! cannot fetch; this harness needs none. Each execution takes one input
//! of a reader's corpus (the repository's own valid files, kept in
//! `xtask/fuzz/<reader>/`), and mutates it as `arbitrary` decides from 512
//! bytes of the execution's own random stream: bit flips, interesting
//! bytes and integers, inserted, deleted, repeated and spliced ranges,
//! truncation, and for text readers numbers and tokens swapped for hostile
//! ones. Binary formats behind a checksum are re-sealed most of the time,
//! so that mutations reach the checks behind it. It is not guided by
//! coverage: it is a black-box fuzzer, and says so in docs/reliability.md.
//!
//! Input `i` of seed `s` depends on nothing else, so a run is reproducible
//! and any input it found can be written again (`--show`). The inputs run
//! in child processes, chunk by chunk, with their address space limited: a
//! panic is caught and reported with its input; an abort (the allocator
//! refused, the stack overflowed) or a chunk that overruns its time is
//! narrowed down to its input by running halves of the chunk again.

mod mutate;
mod targets;

pub(crate) use targets::Reader;
mod corpus;
mod run;

use anyhow::{Result, bail};

pub(crate) use run::{Length, chunk};

/// `cargo xtask fuzz`: fuzz `readers` (every one if none) for `length`
/// from input 0 of `seed`, `jobs` children at a time; report each reader's
/// executions, time per execution and findings, keep each finding's input
/// under target/fuzz/, and fail if there was one.
pub(crate) fn run(
    readers: &[Reader],
    length: Length,
    seed: u64,
    jobs: usize,
    write_corpus: bool,
) -> Result<()> {
    if write_corpus {
        corpus::write()?;
    }
    let readers = if readers.is_empty() {
        &Reader::ALL[..]
    } else {
        readers
    };
    let kept = crate::target_dir().join("fuzz");
    let mut found = 0;
    for &reader in readers {
        let summary = run::fuzz(reader, seed, length, jobs);
        // The files the children wrote, whatever became of them.
        let _ = std::fs::remove_dir_all(targets::scratch_root());
        let summary = summary?;
        println!(
            "{}: {} executions in {:.1} s ({:.1} us each on {jobs} children), {} accepted, {} found",
            reader.name(),
            summary.executions,
            summary.seconds,
            summary.seconds * 1e6 * jobs as f64 / summary.executions.max(1) as f64,
            summary.accepted,
            summary.findings.len()
        );
        let paths = run::keep_findings(reader, seed, &summary.findings, &kept)?;
        for (finding, path) in summary.findings.iter().zip(paths) {
            println!(
                "  input {}: {} ({})",
                finding.index,
                finding.what,
                path.display()
            );
        }
        found += summary.findings.len();
    }
    if found > 0 {
        bail!("{found} inputs made a reader panic, abort or run without end");
    }
    Ok(())
}
