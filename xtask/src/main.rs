//! `cargo xtask`: project automation.
//!
//! `cargo xtask reproduce-paper [--quick] [--out docs/paper]` reruns the
//! paper's experiments and writes a report and the data behind its figures.
//! It covers the two-stage estimator on both examples (Sections 5.3 and
//! 6.2); the competitors join as the baselines crate grows.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use rayon::prelude::*;
use twostage::models::{Benchmark, IoData, PacejkaCar, Simulator, run_experiment};
use twostage::{EstimateWorkspace, Estimator, Preset, TwoStage};

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
        Command::ReproducePaper { quick, out, seed } => reproduce(quick, &out, seed),
        Command::ChartScale { sims, threads } => chart_scale(sims, threads),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
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

/// One experiment of the paper as run here.
struct Section {
    title: &'static str,
    figure: &'static str,
    names: Vec<String>,
    truth: Vec<Vec<f64>>,
    estimates: Vec<Vec<f64>>,
    micros_median: f64,
    train_seconds: f64,
    paper_seconds_per_estimate: f64,
    preset: String,
}

/// Test records are drawn with a seed disjoint from training, calibration
/// and validation (the paper's 200 and 800 fresh experiments).
const TEST_SEED_OFFSET: u64 = 0x5445_5354; // "TEST"

/// A trained estimator and the fresh test records it is judged on.
struct Trained {
    estimator: Estimator,
    truth: Vec<Vec<f64>>,
    records: Vec<IoData>,
    train_seconds: f64,
}

fn run_section<S: Simulator>(
    model: &S,
    preset: Preset,
    m: usize,
    tests: usize,
    seed: u64,
) -> Result<Trained> {
    let start = Instant::now();
    let estimator = TwoStage::builder(model)
        .preset(preset)
        .simulations(m)
        .seed(seed)
        .validation(0)
        .calibration(0)
        .train()?;
    let train_seconds = start.elapsed().as_secs_f64();
    let design = model.prior().design(tests, seed ^ TEST_SEED_OFFSET)?;
    let runs: Vec<(Vec<f64>, IoData)> = (0..tests)
        .into_par_iter()
        .map(|i| {
            let mut theta = vec![0.0; model.prior().dim()];
            let mut record = IoData::default();
            run_experiment(model, &design, i, &mut theta, &mut record).map(|()| (theta, record))
        })
        .collect::<Result<_, _>>()?;
    let (truth, records): (Vec<_>, Vec<_>) = runs.into_iter().unzip();
    Ok(Trained {
        estimator,
        truth,
        records,
        train_seconds,
    })
}

/// Estimate every record, one at a time on one thread, timing each.
fn estimate_all(estimator: &Estimator, records: &[IoData]) -> Result<(Vec<Vec<f64>>, f64)> {
    let mut work = EstimateWorkspace::new();
    let mut times = Vec::with_capacity(records.len());
    let mut estimates = Vec::with_capacity(records.len());
    for record in records {
        let mut theta = vec![0.0; estimator.param_names().len()];
        // Warm the workspace on this record, then time a few repeats.
        estimator.estimate_into(record.inputs(), record.outputs(), &mut work, &mut theta)?;
        let repeats = 20;
        let start = Instant::now();
        for _ in 0..repeats {
            estimator.estimate_into(record.inputs(), record.outputs(), &mut work, &mut theta)?;
        }
        times.push(start.elapsed().as_secs_f64() * 1e6 / repeats as f64);
        estimates.push(theta);
    }
    times.sort_by(f64::total_cmp);
    Ok((estimates, times[times.len() / 2]))
}

fn reproduce(quick: bool, out: &Path, seed: u64) -> Result<()> {
    fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let (bench_m, bench_tests, car_m, car_tests) = if quick {
        (300, 50, 300, 100)
    } else {
        (1500, 200, 2000, 800)
    };
    let mut sections = Vec::new();

    eprintln!("Section 5: benchmark, TS with m = {bench_m}, {bench_tests} test records");
    let bench = Benchmark::new();
    let Trained {
        estimator: est,
        truth,
        records,
        train_seconds,
    } = run_section(
        &bench,
        twostage::paper_benchmark(),
        bench_m,
        bench_tests,
        seed,
    )?;
    let (estimates, micros_median) = estimate_all(&est, &records)?;
    sections.push(Section {
        title: "Section 5: the benchmark system, eq. (5)",
        figure: "figure8",
        names: est.param_names().to_vec(),
        truth,
        estimates,
        micros_median,
        train_seconds,
        paper_seconds_per_estimate: 0.01,
        preset: format!(
            "m = {bench_m}, {}, {}",
            est.compressor(),
            est.training().regressor
        ),
    });

    eprintln!("Section 6: Pacejka car, TS with m = {car_m}, {car_tests} validation records");
    let car = PacejkaCar::new();
    let Trained {
        estimator: est,
        truth,
        records,
        train_seconds,
    } = run_section(&car, twostage::paper_pacejka(), car_m, car_tests, seed)?;
    let (estimates, micros_median) = estimate_all(&est, &records)?;
    sections.push(Section {
        title: "Section 6: the Pacejka car",
        figure: "figure11",
        names: est.param_names().to_vec(),
        truth,
        estimates,
        micros_median,
        train_seconds,
        paper_seconds_per_estimate: 0.01,
        preset: format!(
            "m = {car_m}, {}, {}",
            est.compressor(),
            est.training().regressor
        ),
    });

    let mut report = String::new();
    writeln!(
        report,
        "# Reproduction of Garatti and Bittanti's experiments\n"
    )?;
    writeln!(
        report,
        "Generated by `cargo xtask reproduce-paper{}` (seed {seed}) on {} cores. \
         Estimates are timed one at a time on one thread (median over records).\n",
        if quick { " --quick" } else { "" },
        rayon::current_num_threads()
    )?;
    writeln!(
        report,
        "So far this covers the two-stage (TS) estimator; the paper's competitors \
         (EKF, UKF, particle filter, prediction error) and the Bayes-optimal \
         references are added with the baselines crate.\n"
    )?;
    for s in &sections {
        writeln!(report, "## {}\n", s.title)?;
        writeln!(
            report,
            "TS preset: {}. Training took {:.2} s.\n",
            s.preset, s.train_seconds
        )?;
        writeln!(
            report,
            "| method | parameter | RMSE | largest error | us per estimate (median) | paper's s per estimate |"
        )?;
        writeln!(report, "|---|---|---|---|---|---|")?;
        for (j, name) in s.names.iter().enumerate() {
            let errors: Vec<f64> = s
                .truth
                .iter()
                .zip(&s.estimates)
                .map(|(t, e)| e[j] - t[j])
                .collect();
            let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
            let largest = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            writeln!(
                report,
                "| TS | {name} | {rmse:.4} | {largest:.4} | {:.1} | {} |",
                s.micros_median, s.paper_seconds_per_estimate
            )?;
        }
        let csv_path = out.join(format!("{}.csv", s.figure));
        let mut csv = String::new();
        let header: Vec<String> = s
            .names
            .iter()
            .flat_map(|n| [format!("{n}_true"), format!("{n}_ts")])
            .collect();
        writeln!(csv, "{}", header.join(","))?;
        for (t, e) in s.truth.iter().zip(&s.estimates) {
            let row: Vec<String> = t
                .iter()
                .zip(e)
                .flat_map(|(a, b)| [a.to_string(), b.to_string()])
                .collect();
            writeln!(csv, "{}", row.join(","))?;
        }
        fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
        writeln!(
            report,
            "\nEstimates against truth (the paper's {}): `{}`.\n",
            s.figure,
            csv_path.display()
        )?;
    }
    let path = out.join("REPORT.md");
    fs::write(&path, report).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
