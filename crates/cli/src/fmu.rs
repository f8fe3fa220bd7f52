//! `twostage fmu inspect`: what an FMU offers as parameters, inputs and
//! outputs, and a model file to start from.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use twostage::fmi::{Causality, Fmu, ModelDescription, Variability, Variable};

/// The FMU commands.
#[derive(Debug, Subcommand)]
pub enum FmuCommand {
    /// List the variables that can be parameters, inputs and outputs (units, start
    /// values), and optionally write a starting model file.
    Inspect(InspectArgs),
}

/// Arguments of `twostage fmu inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The FMU (a .fmu archive or an unpacked folder).
    pub fmu: PathBuf,
    /// Write a starting model file here (refuses to overwrite).
    #[arg(long, value_name = "MODEL.toml")]
    pub write: Option<PathBuf>,
    /// Also list the local real variables (they can be measured too).
    #[arg(long)]
    pub locals: bool,
}

/// Run an FMU command.
pub fn run(command: &FmuCommand, out: &mut impl Write) -> Result<()> {
    match command {
        FmuCommand::Inspect(args) => inspect(args, out),
    }
}

fn inspect(args: &InspectArgs, out: &mut impl Write) -> Result<()> {
    let fmu = Fmu::open(&args.fmu)?;
    let md = fmu.description();
    describe(md, args.locals, out)?;
    // Said before any file is written: a model file of an FMU that cannot
    // run here would not train here either.
    let runs_here = fmu.binary_here();
    match &runs_here {
        Ok(binary) => writeln!(out, "binary: {}", binary.display())?,
        Err(_) => writeln!(
            out,
            "binary: none for this platform, so it cannot be simulated here"
        )?,
    }
    if let Some(path) = &args.write {
        // The model file names the FMU relative to its own folder, as the
        // model file's reader resolves it: the pair can move together.
        let folder = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."));
        let fmu_path = match (
            std::fs::canonicalize(folder),
            std::fs::canonicalize(&args.fmu),
        ) {
            (Ok(folder), Ok(fmu)) => pathdiff::diff_paths(&fmu, &folder).unwrap_or(fmu),
            _ => std::path::absolute(&args.fmu).unwrap_or_else(|_| args.fmu.clone()),
        };
        let fmu_name = fmu_path.display().to_string();
        let text = twostage::fmu_model_file(md, &fmu_name);
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .with_context(|| {
                format!(
                    "cannot create {} (it may exist already: choose another name or delete it)",
                    path.display()
                )
            })?;
        file.write_all(text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(
            out,
            "\nwrote {}: check the lines marked CHECK, then\n  twostage train --model-file {} --out estimator.tsest",
            path.display(),
            path.display()
        )?;
    }
    // Inspecting an FMU for another platform is fine; the exit code says
    // that it cannot run here.
    runs_here.map(drop).map_err(anyhow::Error::new)
}

fn describe(md: &ModelDescription, locals: bool, out: &mut impl Write) -> Result<()> {
    writeln!(out, "FMU: {} (FMI {})", md.model_name, md.version)?;
    if let Some(d) = &md.description {
        writeln!(out, "  {d}")?;
    }
    let mut interfaces = Vec::new();
    for interface in [&md.co_simulation, &md.model_exchange]
        .into_iter()
        .flatten()
    {
        let mut text = interface.kind.to_string();
        if interface.once_per_process {
            text.push_str(" (one instance per process: twostage runs it in worker processes)");
        }
        interfaces.push(text);
    }
    writeln!(out, "interfaces: {}", interfaces.join("; "))?;
    if md.model_exchange.is_some() {
        writeln!(
            out,
            "continuous states: {}, event indicators: {}{}",
            md.continuous_states,
            md.event_indicators,
            if md.event_indicators > 0 {
                " (state events: model exchange is refused, use co-simulation)"
            } else {
                ""
            }
        )?;
    }
    let e = md.default_experiment;
    if e.start_time.is_some() || e.stop_time.is_some() || e.step_size.is_some() {
        let show = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
        writeln!(
            out,
            "default experiment: start {}, stop {}, step {}",
            show(e.start_time),
            show(e.stop_time),
            show(e.step_size)
        )?;
    }
    let real = |v: &&Variable| v.is_real_scalar;
    let parameters: Vec<&Variable> = md
        .variables
        .iter()
        .filter(real)
        .filter(|v| {
            v.causality == Causality::Parameter
                && matches!(v.variability, Variability::Fixed | Variability::Tunable)
        })
        .collect();
    let of = |c: Causality| -> Vec<&Variable> {
        md.variables
            .iter()
            .filter(real)
            .filter(|v| v.causality == c)
            .collect()
    };
    table(
        out,
        "parameters (can be estimated or set with start = {...})",
        &parameters,
    )?;
    table(
        out,
        "inputs (driven by [input], or by [noise] inputs)",
        &of(Causality::Input),
    )?;
    table(out, "outputs (can be measured)", &of(Causality::Output))?;
    let local = of(Causality::Local);
    if locals {
        table(out, "local variables (can be measured too)", &local)?;
    } else if !local.is_empty() {
        writeln!(
            out,
            "\n{} local real variable(s) can be measured too: --locals lists them",
            local.len()
        )?;
    }
    let other = md.variables.iter().filter(|v| !v.is_real_scalar).count();
    if other > 0 {
        writeln!(
            out,
            "{other} variable(s) that are not real scalars are not used"
        )?;
    }
    Ok(())
}

fn table(out: &mut impl Write, title: &str, variables: &[&Variable]) -> Result<()> {
    writeln!(out, "\n{title}:")?;
    if variables.is_empty() {
        writeln!(out, "  none")?;
        return Ok(());
    }
    let width = variables
        .iter()
        .map(|v| v.name.len())
        .max()
        .unwrap_or(0)
        .max(4);
    writeln!(
        out,
        "  {:width$}  {:>12}  {:10}  description",
        "name", "start", "unit"
    )?;
    for v in variables {
        writeln!(
            out,
            "  {:width$}  {:>12}  {:10}  {}",
            v.name,
            v.start.map_or_else(|| "-".into(), |s| format!("{s}")),
            v.unit.as_deref().unwrap_or("-"),
            v.description.as_deref().unwrap_or("")
        )?;
    }
    Ok(())
}
