//! `--model NAME` or `--model-file PATH`: the model a command works on, and
//! its presets, whichever way it was named.

use std::path::PathBuf;

use anyhow::Result;
use twostage::models::{BuiltinModel, Simulator};
use twostage::{ModelFile, ModelProfile, Preset};

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

/// A model named on the command line.
pub enum Model {
    /// A built-in model with the paper's settings.
    Builtin(BuiltinModel),
    /// A model file.
    File(Box<ModelFile>),
}

impl ModelArgs {
    /// The model, read and checked.
    pub fn resolve(&self) -> Result<Model> {
        match (&self.model, &self.model_file) {
            (Some(name), None) => {
                Ok(Model::Builtin(name.parse().map_err(|e| {
                    usage(format!("{e} (see `twostage models`)"))
                })?))
            }
            (None, Some(path)) => Ok(Model::File(Box::new(
                ModelFile::load(path).map_err(|e| usage(e.to_string()))?,
            ))),
            _ => Err(usage("give --model NAME or --model-file PATH".into())),
        }
    }
}

impl Model {
    /// Identifies the model's description in shard files: the model
    /// file's text, or the built-in model's name.
    pub fn fingerprint(&self) -> u64 {
        match self {
            Model::Builtin(model) => {
                twostage::fingerprint(format!("builtin:{}", model.name()).as_bytes())
            }
            Model::File(file) => file.fingerprint(),
        }
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        match self {
            Model::Builtin(model) => model.name(),
            Model::File(file) => file.name(),
        }
    }

    /// The simulator, with or without the built-in model's own noise.
    pub fn simulator(&self, noiseless: bool) -> Result<Box<dyn Simulator>> {
        match self {
            Model::Builtin(model) => Ok(model.build(noiseless)?),
            Model::File(_) if noiseless => Err(usage(
                "--noiseless is for built-in models; a model file says `[noise] model = false`"
                    .into(),
            )),
            Model::File(file) => file.simulator().map_err(|e| usage(e.to_string())),
        }
    }

    /// The model for training on charts read from files: a model file
    /// without a source has a spec but nothing to simulate with.
    pub fn chart_model(&self) -> Result<Box<dyn Simulator>> {
        match self {
            Model::Builtin(model) => Ok(model.build(false)?),
            Model::File(file) => file.chart_model().map_err(|e| usage(e.to_string())),
        }
    }

    /// A preset by name; `None` is the model's default (a built-in model's
    /// `paper`, a model file's first).
    pub fn preset(&self, name: Option<&str>) -> Result<Preset> {
        let found = match self {
            Model::Builtin(model) => ModelProfile::of(*model).preset(name.unwrap_or("paper")),
            Model::File(file) => match name {
                Some(name) => file.preset(name),
                None => {
                    let first = file.preset_names().next().unwrap_or("default").to_string();
                    file.preset(&first)
                }
            },
        };
        found.map_err(|e| usage(e.to_string()))
    }
}
