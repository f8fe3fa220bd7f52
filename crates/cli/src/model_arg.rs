//! `--model NAME` or `--model-file PATH`: the model a command works on, and
//! its presets, whichever way it was named.

use std::path::{Path, PathBuf};

use anyhow::Result;
use twostage::models::Simulator;
use twostage::{NamedModel, Preset};

use crate::OrUsage;
use crate::usage;

/// The model options shared by the commands that simulate.
#[derive(Debug, clap::Args)]
pub struct ModelArgs {
    /// A built-in model: benchmark or pacejka (see `twostage models`).
    #[arg(
        long,
        conflicts_with = "model_file",
        required_unless_present = "model_file"
    )]
    pub model: Option<String>,
    /// A model file (TOML; `twostage models --template` prints an annotated one).
    #[arg(long, value_name = "PATH")]
    pub model_file: Option<PathBuf>,
}

/// A model named on the command line: the facade's [`NamedModel`] (which
/// the Python package shares), with its errors as usage errors.
pub struct Model(NamedModel);

impl ModelArgs {
    /// The model, read and checked.
    pub fn resolve(&self) -> Result<Model> {
        named(self.model.as_deref(), self.model_file.as_deref())?
            .map(Model)
            .ok_or_else(|| usage("give --model NAME or --model-file PATH".into()))
    }
}

/// The model named by `--model` (`model`) or `--model-file` (`file`), read
/// and checked; `None` when neither is given. Every command that takes
/// them reads them here (clap refuses both at once).
pub fn named(model: Option<&str>, file: Option<&Path>) -> Result<Option<NamedModel>> {
    match (model, file) {
        (None, None) => Ok(None),
        (_, Some(path)) => NamedModel::file(path).map(Some).or_usage(),
        (Some(name), None) => NamedModel::builtin(name)
            .map(Some)
            .map_err(|e| usage(format!("{e} (see `twostage models`)"))),
    }
}

impl Model {
    /// The facade's model.
    pub fn named(&self) -> &NamedModel {
        &self.0
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        self.0.name()
    }

    /// The simulator, with its noise, or without it where `noiseless`
    /// (refused by a source that cannot run without it).
    pub fn simulator(&self, noiseless: bool) -> Result<Box<dyn Simulator>> {
        let simulator = self.0.simulator().or_usage()?;
        if noiseless {
            Ok(Box::new(
                twostage::models::NoiseFree::new(simulator).or_usage()?,
            ))
        } else {
            Ok(simulator)
        }
    }

    /// A preset by name; `None` is the model's default.
    pub fn preset(&self, name: Option<&str>) -> Result<Preset> {
        self.0.preset(name).or_usage()
    }
}
