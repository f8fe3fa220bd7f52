//! `twostage slurm`: an sbatch array script that simulates a training
//! run's charts in shards, and the command that merges them.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use twostage::RunSettings;

use crate::model_arg::ModelArgs;
use crate::usage;

/// Options of `twostage slurm`.
#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Training simulations m (as `train --sims`).
    #[arg(long)]
    count: usize,
    /// Validation simulations (as `train --validate`).
    #[arg(long, default_value_t = RunSettings::default().validation)]
    validate: usize,
    /// Calibration simulations (as `train --calibrate`).
    #[arg(long, default_value_t = RunSettings::default().calibration)]
    calibrate: usize,
    /// Seed of the run (as `train --seed`).
    #[arg(long, default_value_t = twostage::DEFAULT_SEED)]
    seed: u64,
    /// Number of shards: the array's tasks.
    #[arg(long)]
    shards: usize,
    /// The folder of the shard files (and of the tasks' logs, in logs/).
    #[arg(long)]
    out: PathBuf,
    /// Store features of this stage-1 compressor (arx:NA,NB, ar:NA, raw)
    /// instead of raw records.
    #[arg(long)]
    compress: Option<String>,
    /// sbatch --time of each task (e.g. 02:00:00).
    #[arg(long)]
    time: Option<String>,
    /// sbatch --partition.
    #[arg(long)]
    partition: Option<String>,
    /// sbatch --cpus-per-task (the task's simulation threads).
    #[arg(long, default_value_t = 1)]
    cpus_per_task: usize,
    /// sbatch --mem of each task, in megabytes.
    #[arg(long)]
    mem_mb: Option<usize>,
    /// Where to write the script (default OUT/chart.sbatch).
    #[arg(long)]
    script: Option<PathBuf>,
}

/// Quote `text` for a POSIX shell.
fn quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', "'\\''"))
}

fn absolute(path: &Path) -> Result<String> {
    Ok(std::path::absolute(path)
        .with_context(|| format!("resolving {}", path.display()))?
        .display()
        .to_string())
}

/// Write the array script and say how to run and merge it.
pub fn slurm(args: &SlurmArgs, out: &mut dyn Write) -> Result<()> {
    if args.shards == 0 || args.count == 0 {
        return Err(usage("--shards and --count must be at least 1".into()));
    }
    let model = args.model.resolve()?;
    // The model is built now, so that a mistake shows here, not in N tasks.
    model.simulator(false)?;
    let exe = std::env::current_exe().context("finding the twostage binary")?;
    let dir = absolute(&args.out)?;
    let model_arg = match (&args.model.model, &args.model.model_file) {
        (_, Some(file)) => format!("--model-file {}", quote(&absolute(file)?)),
        (Some(name), None) => format!("--model {}", quote(name)),
        (None, None) => unreachable!("resolve() needs one"),
    };
    let mut command = format!(
        "{} simulate {model_arg} --count {} --validate {} --calibrate {} --seed {} --shard \"auto/{}\" --out {}",
        quote(&exe.display().to_string()),
        args.count,
        args.validate,
        args.calibrate,
        args.seed,
        args.shards,
        quote(&dir),
    );
    if let Some(spec) = &args.compress {
        command.push_str(&format!(" --compress {}", quote(spec)));
    }
    let mut directives = vec![
        format!("--job-name=twostage-{}", model.name()),
        format!("--array=0-{}", args.shards - 1),
        format!("--output={dir}/logs/shard-%a.log"),
        format!("--cpus-per-task={}", args.cpus_per_task),
    ];
    if let Some(t) = &args.time {
        directives.push(format!("--time={t}"));
    }
    if let Some(p) = &args.partition {
        directives.push(format!("--partition={p}"));
    }
    if let Some(mb) = args.mem_mb {
        directives.push(format!("--mem={mb}M"));
    }
    let script = format!(
        "#!/bin/bash\n\
         # Written by `twostage slurm`: an array of {n} tasks, each simulating one\n\
         # shard of the charts of a training run of {name} ({m} training, {c}\n\
         # calibration and {r} validation records, seed {seed}). Merge with\n\
         #   twostage train {model_arg} --chart '{dir}/shard-*' --out estimator.tsest\n\
         # Re-run failed shards alone with sbatch --array=I,J this-script.\n\
         {directives}\n\
         set -euo pipefail\n\
         export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n\
         exec {command}\n",
        n = args.shards,
        name = model.name(),
        m = args.count,
        c = args.calibrate,
        r = args.validate,
        seed = args.seed,
        directives = directives
            .iter()
            .map(|d| format!("#SBATCH {d}"))
            .collect::<Vec<_>>()
            .join("\n"),
    );
    std::fs::create_dir_all(Path::new(&dir).join("logs"))
        .with_context(|| format!("creating {dir}/logs"))?;
    let path = args
        .script
        .clone()
        .unwrap_or_else(|| Path::new(&dir).join("chart.sbatch"));
    twostage::write_whole(&path, script.as_bytes())?;
    writeln!(
        out,
        "wrote {script}: {n} shards of {dir}\n\
         run:    sbatch {script}\n\
         merge:  twostage train {model_arg} --chart '{dir}/shard-*' --out estimator.tsest\n\
         failed shards are named by the merge; re-run them alone with sbatch --array=I,J {script}",
        script = path.display(),
        n = args.shards,
    )?;
    Ok(())
}
