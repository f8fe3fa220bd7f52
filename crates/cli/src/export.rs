//! `twostage export`: an estimator for somewhere else (the microcontroller
//! runtime's blob).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use twostage::Estimator;

/// Where an exported estimator goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportTarget {
    /// The no_std runtime and its C API (`twostage-runtime`): a versioned,
    /// checksummed blob read in place (docs/embedded.md).
    Runtime,
}

/// Arguments of `twostage export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The estimator file (from `twostage train`).
    #[arg(long)]
    pub estimator: PathBuf,
    /// What to export to.
    #[arg(long, value_enum, default_value = "runtime")]
    pub to: ExportTarget,
    /// Where to write it (by convention NAME.tsrt).
    #[arg(long)]
    pub out: PathBuf,
    /// Leave the posterior's density out of the blob: the estimate, its
    /// intervals and flags as with it, no draws, fewer bytes of flash.
    #[arg(long)]
    pub without_posterior: bool,
}

/// Run `twostage export`.
pub fn export(args: &ExportArgs, out: &mut dyn Write) -> Result<()> {
    let mut estimator = Estimator::load(&args.estimator)?;
    if args.without_posterior {
        estimator = estimator.without_posterior();
    }
    match args.to {
        ExportTarget::Runtime => {
            let blob = estimator
                .to_runtime()
                .with_context(|| format!("exporting {}", args.estimator.display()))?;
            let runtime = twostage::runtime::Estimator::from_bytes(&blob)
                .context("the exported blob does not read back")?;
            twostage::write_whole(&args.out, &blob)?;
            writeln!(
                out,
                "wrote {} ({} bytes): {} parameter(s) from {} input(s) and {} output(s), {} \
                 stage-1 features; a stream needs a workspace of {} numbers ({} bytes)",
                args.out.display(),
                blob.len(),
                runtime.n_parameters(),
                runtime.n_inputs(),
                runtime.n_outputs(),
                runtime.n_features(),
                runtime.workspace_len(),
                8 * runtime.workspace_len()
            )?;
            if !estimator.fixed().is_empty() {
                writeln!(
                    out,
                    "it estimates {}; {} held while training, not in the blob",
                    estimator.param_names().join(", "),
                    estimator.fixed()
                )?;
            }
            if runtime.has_posterior() {
                writeln!(
                    out,
                    "it carries the posterior: a stream's finish_with_draws (C: \
                     ts_stream_finish_draws) draws what `estimate --samples N --seed S` draws \
                     for the same seed and record number; --without-posterior leaves it out"
                )?;
            }
        }
    }
    Ok(())
}
