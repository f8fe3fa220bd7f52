//! A model named by its user: a built-in model's name or a model file's
//! path, with its simulator, its charts-only form and its presets, so the
//! command line and the Python package resolve names the same way.

use std::borrow::Cow;
use std::path::Path;

use twostage_models::{BuiltinModel, Simulator};

use crate::error::{Error, Result};
use crate::fingerprint;
use crate::model_file::{ModelFile, ModelSource};
use crate::preset::Preset;
use crate::profile::ModelProfile;

/// A built-in model or a model file.
///
/// ```
/// use twostage_sources::NamedModel;
/// let model = NamedModel::builtin("benchmark")?;
/// assert_eq!(model.name(), "benchmark");
/// // A built-in model's default preset is the paper's.
/// assert_eq!(model.preset(None)?.simulations, 1500);
/// assert!(NamedModel::builtin("pendulum").is_err());
/// // A model file with a built-in source keeps that model's presets.
/// let file = twostage_sources::ModelFile::parse(
///     "[model]\nname = \"short\"\n[source]\nbuiltin = \"benchmark\"\n\
///      [signals]\nsamples = 300\n[[preset]]\nname = \"small\"\ncompress = \"arx:3,3\"\n\
///      fit = \"mlp:6\"\nsims = 800\n",
///     "short.toml",
/// )?;
/// let short = NamedModel::File(Box::new(file));
/// assert_eq!(short.preset_names(), ["small", "paper", "recommended"]);
/// assert_eq!(short.preset(None)?.simulations, 800);
/// assert_eq!(short.preset(Some("paper"))?.simulations, 1500);
/// # Ok::<(), twostage_sources::Error>(())
/// ```
#[derive(Debug, Clone)]
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

    /// The built-in model, where this is one (a model file is not, even
    /// one over a built-in source: its settings are its own).
    ///
    /// ```
    /// use twostage_sources::NamedModel;
    /// use twostage_models::BuiltinModel;
    /// assert_eq!(NamedModel::builtin("pacejka")?.as_builtin(), Some(BuiltinModel::Pacejka));
    /// # Ok::<(), twostage_sources::Error>(())
    /// ```
    pub fn as_builtin(&self) -> Option<BuiltinModel> {
        match self {
            Self::Builtin(model) => Some(*model),
            Self::File(_) => None,
        }
    }

    /// The model file whose text is `text`; `origin` names it in messages
    /// (as a path would).
    ///
    /// # Errors
    /// As [`ModelFile::parse`].
    pub fn text(text: &str, origin: &str) -> Result<Self> {
        Ok(Self::File(Box::new(ModelFile::parse(text, origin)?)))
    }

    /// The model whose records an estimator trained on the model called
    /// `trained_on` reads, to check, refine or validate them against:
    /// `given` where it describes that model, else the built-in model of
    /// that name. Every door (the command line's commands, the Python
    /// package) finds it here, so that they accept and refuse alike.
    ///
    /// ```
    /// use twostage_sources::NamedModel;
    /// let model = NamedModel::trained_on("benchmark", None)?;
    /// assert_eq!(model.name(), "benchmark");
    /// let short = NamedModel::text(
    ///     "[model]\nname = \"short\"\n[source]\nbuiltin = \"benchmark\"\n",
    ///     "short.toml",
    /// )?;
    /// assert_eq!(NamedModel::trained_on("short", Some(&short))?.name(), "short");
    /// // A model file of another model, or none for a model that is not built in.
    /// let other = NamedModel::trained_on("benchmark", Some(&short)).unwrap_err();
    /// assert!(other.to_string().starts_with("short.toml describes 'short'"));
    /// assert!(NamedModel::trained_on("short", None).is_err());
    /// # Ok::<(), twostage_sources::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::OtherModel`]: `given` describes another model, or none is
    /// given and `trained_on` is not a built-in model.
    pub fn trained_on<'a>(trained_on: &str, given: Option<&'a Self>) -> Result<Cow<'a, Self>> {
        match given {
            Some(given) if given.name() == trained_on => Ok(Cow::Borrowed(given)),
            Some(given) => Err(Error::OtherModel {
                trained_on: trained_on.to_string(),
                given: Some((given.origin().to_string(), given.name().to_string())),
            }),
            None => Self::builtin(trained_on)
                .map(Cow::Owned)
                .map_err(|_| Error::OtherModel {
                    trained_on: trained_on.to_string(),
                    given: None,
                }),
        }
    }

    /// Where the model was named: a model file's path (or the name its
    /// text was given), or "built-in model 'NAME'".
    pub fn origin(&self) -> Cow<'_, str> {
        match self {
            Self::Builtin(model) => Cow::Owned(format!("built-in model '{}'", model.name())),
            Self::File(file) => Cow::Borrowed(file.origin()),
        }
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

    /// The simulator, with its noise (a run without it is the run's
    /// condition: `Conditions::noiseless`, or the simulator wrapped in
    /// `NoiseFree`, for any source that can run without it).
    ///
    /// # Errors
    /// What starting the model file's source reports.
    pub fn simulator(&self) -> Result<Box<dyn Simulator>> {
        match self {
            Self::Builtin(model) => Ok(model.build()?),
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
            Self::Builtin(model) => Ok(model.build()?),
            Self::File(file) => file.chart_model(),
        }
    }

    /// The names of the model's presets: a built-in model's; a model
    /// file's own, in its order, then those of a built-in source that the
    /// file does not shadow.
    pub fn preset_names(&self) -> Vec<String> {
        let builtin = self.builtin_profile().map(ModelProfile::preset_names);
        let mut names: Vec<String> = match self {
            Self::Builtin(_) => Vec::new(),
            Self::File(file) => file.preset_names().map(str::to_string).collect(),
        };
        for name in builtin.into_iter().flatten() {
            if !names.iter().any(|n| n == name) {
                names.push(name.to_string());
            }
        }
        names
    }

    /// A preset by name; `None` is the model's default (a built-in model's
    /// `paper`, a model file's first, then its built-in source's).
    ///
    /// # Errors
    /// An unknown preset name; the message lists the model's presets.
    pub fn preset(&self, name: Option<&str>) -> Result<Preset> {
        match self {
            Self::Builtin(model) => ModelProfile::of(*model).preset(name.unwrap_or("paper")),
            Self::File(file) => {
                let names = self.preset_names();
                let name = name
                    .map(str::to_string)
                    .or_else(|| names.first().cloned())
                    .unwrap_or_else(|| "default".into());
                if file.preset_names().any(|n| n == name) {
                    return file.preset(&name);
                }
                match self.builtin_profile() {
                    Some(profile) if profile.preset_names().any(|n| n == name) => {
                        profile.preset(&name)
                    }
                    _ => Err(Error::NotAvailable {
                        what: "preset",
                        name,
                        model: self.name().to_string(),
                        available: if names.is_empty() {
                            "none (add a [[preset]], or give the stages on the command line)".into()
                        } else {
                            names.join(", ")
                        },
                    }),
                }
            }
        }
    }

    /// The per-model table of a built-in model, or of a model file's
    /// built-in source.
    fn builtin_profile(&self) -> Option<&'static ModelProfile> {
        match self {
            Self::Builtin(model) => Some(ModelProfile::of(*model)),
            Self::File(file) => match file.source() {
                ModelSource::Builtin { model, .. } => Some(ModelProfile::of(*model)),
                _ => None,
            },
        }
    }
}
