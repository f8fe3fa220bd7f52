//! `twostage`: the command line of the two-stage estimator toolkit.

mod bars;
mod curve;
mod demo;
mod estimate;
mod export;
mod fmu;
mod inspect;
mod model_arg;
mod models;
mod number;
mod options;
mod predict;
mod simulate;
mod slurm;
mod specs;
mod standard_output;
mod train;
mod validate;

use std::fmt;
use std::io::{self, Write};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use standard_output::StandardOutput;

/// Turn a simulator into a microsecond-fast parameter estimator (Garatti and
/// Bittanti's two-stage method), and simulate the paper's models.
#[derive(Debug, Parser)]
#[command(name = "twostage", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Train the paper's benchmark estimator, validate it, and estimate a fresh record.
    Demo(demo::DemoArgs),
    /// List the built-in models (parameters, priors, sampling, input, noise), describe a
    /// model file's (--model-file), or print an annotated model file (--template).
    Models(models::ModelsArgs),
    /// Simulate one experiment (--theta) or many drawn from the prior (--count).
    Simulate(simulate::SimulateArgs),
    /// Train an estimator for a built-in model or a model file and write it to a file.
    Train(train::TrainArgs),
    /// Describe an estimator file: model, structure, training, validation.
    Inspect {
        /// The estimator file.
        file: std::path::PathBuf,
        /// As JSON: the training, the priors and the validation report
        /// with its certificates.
        #[command(flatten)]
        format: options::FormatArgs,
    },
    /// Estimate the parameters of recorded experiments (CSV u,y or experiment,u,y).
    Estimate(estimate::EstimateArgs),
    /// Check an estimator on fresh simulations: accuracy, certificates, interval coverage.
    Validate(validate::ValidateArgs),
    /// Validation RMSE against the number of training simulations (m doubling).
    LearningCurve(curve::CurveArgs),
    /// Write an sbatch array script that simulates a training run's charts in shards on
    /// a Slurm cluster, and print the command that merges them (docs/cluster.md).
    Slurm(slurm::SlurmArgs),
    /// Export an estimator for the no_std runtime, its C API and microcontrollers
    /// (docs/embedded.md).
    Export(export::ExportArgs),
    /// FMUs (FMI 2.0 and 3.0): list what one offers and write a model file to start from.
    Fmu {
        #[command(subcommand)]
        command: fmu::FmuCommand,
    },
}

/// A mistake in how the command was called: exit code 2, like clap's own.
#[derive(Debug)]
pub enum UsageError {
    /// Said in words.
    Said(String),
    /// A library's error about what the user gave, kept as it is (its
    /// causes with it).
    Caused(Box<dyn std::error::Error + Send + Sync>),
}

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Said(message) => f.write_str(message),
            Self::Caused(error) => fmt::Display::fmt(error, f),
        }
    }
}

impl std::error::Error for UsageError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Said(_) => None,
            Self::Caused(error) => error.source(),
        }
    }
}

/// Wrap a usage mistake so that `main` exits with code 2.
pub fn usage(message: String) -> anyhow::Error {
    anyhow::Error::new(UsageError::Said(message))
}

/// A library's error as a usage mistake (exit code 2), the error kept.
pub trait OrUsage<T> {
    /// The error as it is, marked as the user's mistake.
    ///
    /// # Errors
    /// The error of `self`.
    fn or_usage(self) -> anyhow::Result<T>;
    /// The error in the context of `what` (an option, a file), marked as
    /// the user's mistake.
    ///
    /// # Errors
    /// The error of `self`.
    fn usage_context(self, what: &str) -> anyhow::Result<T>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> OrUsage<T> for Result<T, E> {
    fn or_usage(self) -> anyhow::Result<T> {
        self.map_err(|e| anyhow::Error::new(UsageError::Caused(Box::new(e))))
    }

    fn usage_context(self, what: &str) -> anyhow::Result<T> {
        self.map_err(|e| anyhow::Error::new(e).context(UsageError::Said(what.to_string())))
    }
}

fn main() -> ExitCode {
    // Started as an FMU worker, serve the parent and exit; else let
    // once-per-process FMUs run in worker processes of this binary.
    twostage::fmi::serve_workers_from_this_program();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // clap prints help and version to stdout (exit 0) and usage errors
        // to stderr (exit 2).
        Err(e) => e.exit(),
    };
    let result = match &cli.command {
        Command::Demo(args) => demo::demo(args, &mut StandardOutput::lock()),
        Command::Models(args) => models::models(args, &mut StandardOutput::lock()),
        Command::Simulate(args) => simulate::simulate(args),
        Command::Train(args) => train::train(args, &mut StandardOutput::lock()),
        Command::Inspect { file, format } => {
            inspect::inspect(file, format.json(), &mut StandardOutput::lock())
        }
        Command::Validate(args) => validate::validate(args, &mut StandardOutput::lock()),
        Command::LearningCurve(args) => curve::learning_curve(args, &mut StandardOutput::lock()),
        Command::Slurm(args) => slurm::slurm(args, &mut StandardOutput::lock()),
        Command::Export(args) => export::export(args, &mut StandardOutput::lock()),
        Command::Fmu { command } => fmu::run(command, &mut StandardOutput::lock()),
        Command::Estimate(args) => estimate::estimate(args).and_then(|outcome| {
            outcome
                .failure()
                .map_or(Ok(()), |message| Err(anyhow::anyhow!(message)))
        }),
    };
    // What the command printed last may still sit in the buffer.
    let result = result.and_then(|()| Ok(StandardOutput::lock().flush()?));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<UsageError>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// `twostage simulate ... | head` closes our stdout early: not an error.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<io::Error>()
            .is_some_and(|io| io.kind() == io::ErrorKind::BrokenPipe)
    })
}
