//! `cargo xtask`: project automation.
//!
//! `cargo xtask reproduce-paper [--quick] [--out docs/paper]` reruns the
//! paper's experiments and writes a report and the data behind its figures.
//! Every method of Sections 5 and 6 runs on the same fresh records: EKF,
//! UKF, particle filter, prediction error with 1, 5 and 10 starts, the
//! two-stage estimator, and the Bayes-optimal references.
//!
//! `cargo xtask crates` draws the crates and their arrows, and finds the
//! circles among each crate's modules.
//!
//! `cargo xtask test` runs the whole test suite with what its external
//! programs need (a Python virtual environment with numpy under target/).

use std::fs;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use twostage::models::{Benchmark, Simulator};

mod bayes_gap;
mod c2st;
mod crates;
mod fit_speed;
mod flag_study;
mod fuzz;
mod learned_summary;
mod paper;
mod posterior_cache;
mod test;

#[derive(Debug, Parser)]
#[command(name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Rerun the paper's experiments; write REPORT.md and figure data.
    ReproducePaper {
        /// Reduced sizes through the same code, for CI.
        #[arg(long)]
        quick: bool,
        /// Output folder.
        #[arg(long, default_value = "docs/paper")]
        out: PathBuf,
        /// Seed of training and test sets.
        #[arg(long, default_value_t = 2013)]
        seed: u64,
    },
    /// The whole test suite, with the Python environment some tests need
    /// (set up under target/venv on first use); arguments go to cargo test.
    Test {
        /// Passed on to `cargo test --workspace`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// An estimator of a built-in model against the Bayes posterior mean on
    /// the same fresh records: both RMSEs and their ratio, per parameter.
    BayesGap {
        /// The estimator file (trained on the built-in benchmark or car, or
        /// on a model file of one: then name it with --model).
        #[arg(long)]
        estimator: PathBuf,
        /// A second estimator, set beside the first on the same records.
        #[arg(long)]
        against: Option<PathBuf>,
        /// The built-in model the test records are of (default: the one
        /// the estimator was trained on).
        #[arg(long)]
        model: Option<twostage::models::BuiltinModel>,
        /// What steers the car in the test records.
        #[arg(long, value_enum, default_value = "chicane")]
        steering: bayes_gap::Steering,
        /// Fresh test records.
        #[arg(long, default_value_t = 2000)]
        records: usize,
        /// Seed of the test records (kept apart from training seeds).
        #[arg(long, default_value_t = 2026)]
        seed: u64,
        /// Test on the records of this chart folder (as `twostage simulate
        /// --count --out-dir` writes it, steered as --steering says)
        /// instead of fresh ones: so that `twostage estimate`'s own output
        /// on them (--refine, --check) can be scored with --estimates.
        #[arg(long)]
        chart: Option<PathBuf>,
        /// Estimates of the chart's records as `twostage estimate` writes
        /// them (an `experiment` column and one per parameter, in the
        /// chart's order), scored beside the estimator; repeatable.
        #[arg(long, requires = "chart")]
        estimates: Vec<PathBuf>,
        /// Test the estimator's posterior draws against the exact
        /// posterior's by a classifier (sbibm's C2ST) on this many of the
        /// records.
        #[arg(long, default_value_t = 0)]
        c2st: usize,
        /// With --c2st: score these draws (as `twostage estimate --draws`
        /// writes them, say sharpened) instead of the estimator's own, their
        /// experiments taken in the records' order (`--chart` the folder the
        /// draws' records came from).
        #[arg(long, requires = "c2st")]
        draws: Option<PathBuf>,
    },
    /// The classifier two-sample test (sbibm's C2ST) between two files
    /// of posterior draws, as `twostage estimate --draws` writes them:
    /// each experiment of the first against the same of the second.
    C2st {
        /// Draws to score (say `twostage estimate --samples 10000 --draws`).
        first: PathBuf,
        /// Reference draws of the same experiments and parameters.
        second: PathBuf,
        /// Seed of the classifiers and the folds.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// A stage 1 that learns against the family estimator's own: a summary
    /// network trained on a model file's family, stage 2 fitted on its
    /// summary (alone and beside the estimator's features), each against
    /// the exact posterior mean on the car's manoeuvres.
    LearnedSummary(learned_summary::Args),
    /// Which flag knows when an estimate is far from what its record
    /// allows: the features' density and the ensemble's disagreement,
    /// each calibrated on the family, against the exact posterior mean on
    /// the car's manoeuvres.
    FlagStudy(flag_study::Args),
    /// The workspace's crates: lines, workspace dependencies, and circles
    /// among each crate's top-level modules (Markdown, for docs/crates.md).
    Crates {
        /// Fail if any crate has a module circle.
        #[arg(long)]
        check: bool,
    },
    /// The stage-2 fit alone: a model's charts compressed once, the fit
    /// timed and scored on the validation chart (optionally written as CSV
    /// for another tool to fit the same features).
    FitSpeed {
        /// A built-in model's name or a model file.
        #[arg(long)]
        model: String,
        /// Stage 1, as `train --compress` takes it.
        #[arg(long, default_value = "arx:4,4")]
        compress: String,
        /// Stage 2, as `train --fit` takes it.
        #[arg(long, default_value = "mlp:32")]
        fit: String,
        /// Training records.
        #[arg(long, default_value_t = 4000)]
        sims: usize,
        /// Validation records.
        #[arg(long, default_value_t = 10_000)]
        validate: usize,
        /// Seed of the charts and the fit.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Fits timed (the median is reported).
        #[arg(long, default_value_t = 1)]
        repeats: usize,
        /// Write the charts as CSV into this folder.
        #[arg(long)]
        export: Option<PathBuf>,
        /// A network's trainer instead of its own: lm, adam or lbfgs:N.
        /// With --first-rows, the trainer of the second phase only.
        #[arg(long)]
        trainer: Option<String>,
        /// Fit on the first S training records with the network's own
        /// trainer, then train that fit further on all of them (the
        /// automatic design's anytime steps), timing and scoring each phase.
        #[arg(long, value_name = "S")]
        first_rows: Option<usize>,
    },
    /// Fuzz the readers of outside data (estimator files, runtime blobs,
    /// model files, CSV rows) with inputs mutated from their corpus in
    /// xtask/fuzz/; a panic, an abort or endless work fails the run, and
    /// the input is kept under target/fuzz/.
    Fuzz {
        /// The readers (default: every one).
        #[arg(long = "reader", value_enum)]
        readers: Vec<fuzz::Reader>,
        /// Inputs per reader (a reproducible run; the default).
        #[arg(long, default_value_t = 100_000, conflicts_with = "seconds")]
        execs: u64,
        /// Fuzz each reader for this many seconds instead.
        #[arg(long)]
        seconds: Option<f64>,
        /// Seed of the inputs' random streams.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Child processes at a time.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
        /// First write each reader's corpus again from the repository's
        /// files and small estimators trained here.
        #[arg(long)]
        write_corpus: bool,
    },
    /// One fuzzing child's chunk of inputs (started by `fuzz`).
    #[command(hide = true)]
    FuzzChunk {
        #[arg(long, value_enum)]
        reader: fuzz::Reader,
        #[arg(long)]
        seed: u64,
        #[arg(long)]
        from: u64,
        #[arg(long)]
        count: u64,
    },
    /// Simulate and compress a large benchmark chart; report throughput and
    /// peak memory (the bounded-memory claim of DESIGN.md).
    ChartScale {
        /// Number of simulations m.
        #[arg(long, default_value_t = 1_000_000)]
        sims: usize,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::ReproducePaper { quick, out, seed } => paper::reproduce(quick, &out, seed),
        Command::ChartScale { sims, threads } => chart_scale(sims, threads),
        Command::Test { args } => test::run(&args),
        Command::FitSpeed {
            model,
            compress,
            fit,
            sims,
            validate,
            seed,
            repeats,
            export,
            trainer,
            first_rows,
        } => fit_speed::run(&fit_speed::FitSpeed {
            model: &model,
            compress: &compress,
            fit: &fit,
            sims,
            validate,
            seed,
            repeats,
            export: export.as_deref(),
            trainer: trainer.as_deref(),
            first_rows,
        }),
        Command::Crates { check } => crates::run(check),
        Command::Fuzz {
            readers,
            execs,
            seconds,
            seed,
            jobs,
            write_corpus,
        } => {
            let length = seconds.map_or(fuzz::Length::Executions(execs), fuzz::Length::Seconds);
            fuzz::run(&readers, length, seed, jobs, write_corpus)
        }
        Command::FuzzChunk {
            reader,
            seed,
            from,
            count,
        } => fuzz::chunk(reader, seed, from, count),
        Command::C2st {
            first,
            second,
            seed,
        } => c2st::files(&first, &second, seed),
        Command::LearnedSummary(args) => learned_summary::run(&args),
        Command::FlagStudy(args) => flag_study::run(&args),
        Command::BayesGap {
            estimator,
            against,
            model,
            steering,
            records,
            seed,
            chart,
            estimates,
            c2st,
            draws,
        } => bayes_gap::run(
            &estimator,
            against.as_deref(),
            bayes_gap::TestRecords {
                model,
                steering,
                count: records,
                seed,
                chart,
            },
            &estimates,
            (c2st, draws.as_deref()),
        ),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The workspace's target directory: what the tasks keep between runs
/// (posterior means, fuzzing findings) goes there, and `cargo clean`
/// empties it.
fn target_dir() -> PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("target"), |root| root.join("target"))
}

/// Peak resident memory of this process (VmHWM), in MiB, where /proc has it.
fn peak_memory_mib() -> Option<f64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn chart_scale(sims: usize, threads: Option<usize>) -> Result<()> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .context("starting the thread pool")?;
    let workers = pool.current_num_threads();
    let model = Benchmark::new();
    let arx = twostage::compress::Arx::new(5, 5)?;
    let design = model.prior().design(sims, 1)?;
    let start = Instant::now();
    let chart = pool.install(|| twostage::compress_chart(&model, &arx, &design, "scale", 0.0))?;
    let seconds = start.elapsed().as_secs_f64();
    let per_core = sims as f64 / seconds / workers as f64;
    println!(
        "{sims} benchmark simulations (N = 1000) compressed to ARX(5, 5) on {workers} threads \
         in {seconds:.2} s: {:.0} simulations/s, {per_core:.0} per thread-second",
        sims as f64 / seconds
    );
    println!(
        "chart {} x {} features; peak resident memory {}",
        chart.features.nrows(),
        chart.features.ncols(),
        peak_memory_mib().map_or("unknown".into(), |m| format!("{m:.0} MiB"))
    );
    Ok(())
}
