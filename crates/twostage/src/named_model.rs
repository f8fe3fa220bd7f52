//! A model named by its user: a built-in model's name or a model file's
//! path, with its simulator, its charts-only form and its presets, so the
//! command line and the Python package resolve names the same way.

use std::path::Path;

use twostage_models::{BuiltinModel, Simulator};

use crate::builder::Preset;
use crate::error::{Error, Result};
use crate::model_file::ModelFile;
use crate::profile::ModelProfile;
use crate::shard::fingerprint;

/// A built-in model or a model file.
///
/// ```
/// use twostage::NamedModel;
/// let model = NamedModel::builtin("benchmark")?;
/// assert_eq!(model.name(), "benchmark");
/// // A built-in model's default preset is the paper's.
/// assert_eq!(model.preset(None)?.simulations, 1500);
/// assert!(NamedModel::builtin("pendulum").is_err());
/// # Ok::<(), twostage::Error>(())
/// ```
#[derive(Debug)]
pub enum NamedModel {
    /// A built-in model with the paper's settings.
    Builtin(BuiltinModel),
    /// A model file.
    File(Box<ModelFile>),
}

impl NamedModel {
    /// The built-in model called `name` (case-insensitive).
    ///
    /// # Errors
    /// An unknown name; the message lists the known ones.
    pub fn builtin(name: &str) -> Result<Self> {
        Ok(Self::Builtin(name.parse()?))
    }

    /// The model file at `path`, read and checked.
    ///
    /// # Errors
    /// As [`ModelFile::load`].
    pub fn file(path: impl AsRef<Path>) -> Result<Self> {
        Ok(Self::File(Box::new(ModelFile::load(path)?)))
    }

    /// Identifies the model's description in shard files: the model
    /// file's text, or the built-in model's name.
    pub fn fingerprint(&self) -> u64 {
        match self {
            Self::Builtin(model) => fingerprint(format!("builtin:{}", model.name()).as_bytes()),
            Self::File(file) => file.fingerprint(),
        }
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        match self {
            Self::Builtin(model) => model.name(),
            Self::File(file) => file.name(),
        }
    }

    /// The simulator, with or without the built-in model's own noise.
    ///
    /// # Errors
    /// `noiseless` for a model file (its `[noise]` table decides), or what
    /// starting the model file's source reports.
    pub fn simulator(&self, noiseless: bool) -> Result<Box<dyn Simulator>> {
        match self {
            Self::Builtin(model) => Ok(model.build(noiseless)?),
            Self::File(_) if noiseless => Err(Error::InvalidSetting {
                name: "noiseless",
                value: "true".into(),
                reason: "is for built-in models; a model file says `[noise] model = false`".into(),
            }),
            Self::File(file) => file.simulator(),
        }
    }

    /// The model for training on charts read from files: a model file
    /// without a source has a spec but nothing to simulate with.
    ///
    /// # Errors
    /// As [`ModelFile::chart_model`].
    pub fn chart_model(&self) -> Result<Box<dyn Simulator>> {
        match self {
            Self::Builtin(model) => Ok(model.build(false)?),
            Self::File(file) => file.chart_model(),
        }
    }

    /// A preset by name; `None` is the model's default (a built-in model's
    /// `paper`, a model file's first).
    ///
    /// # Errors
    /// An unknown preset name; the message lists the model's presets.
    pub fn preset(&self, name: Option<&str>) -> Result<Preset> {
        match self {
            Self::Builtin(model) => ModelProfile::of(*model).preset(name.unwrap_or("paper")),
            Self::File(file) => match name {
                Some(name) => file.preset(name),
                None => {
                    let first = file.preset_names().next().unwrap_or("default").to_string();
                    file.preset(&first)
                }
            },
        }
    }
}
