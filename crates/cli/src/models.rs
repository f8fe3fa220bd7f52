//! `twostage models`: the built-in models, or a model file's, described as
//! the commands see them; or the annotated model-file template.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use twostage::models::BuiltinModel;
use twostage::{ModelProfile, NamedModel};

use crate::OrUsage;
use crate::number::format_f64;

/// Options of `twostage models`.
#[derive(Debug, clap::Args)]
pub struct ModelsArgs {
    /// Print an annotated model file to start your own from.
    #[arg(long, conflicts_with = "model_file")]
    template: bool,
    /// Describe this model file's model instead of the built-in ones.
    #[arg(long, value_name = "PATH")]
    model_file: Option<PathBuf>,
}

/// Run `twostage models`.
pub fn models(args: &ModelsArgs, out: &mut dyn Write) -> Result<()> {
    if args.template {
        out.write_all(twostage::MODEL_FILE_TEMPLATE.as_bytes())?;
        return Ok(());
    }
    if let Some(path) = &args.model_file {
        let named = NamedModel::file(path).or_usage()?;
        return describe(&named, out);
    }
    for model in BuiltinModel::ALL {
        describe(&NamedModel::Builtin(model), out)?;
    }
    Ok(())
}

/// One model as the commands see it: parameters and priors, record,
/// signals, input, noise, presets and classic methods.
fn describe(named: &NamedModel, out: &mut dyn Write) -> Result<()> {
    let sim = named.chart_model()?;
    let spec = sim.spec();
    let summary = match named {
        NamedModel::Builtin(model) => model.summary().to_string(),
        NamedModel::File(file) => file.description().to_string(),
    };
    writeln!(out, "{}: {summary}", named.name())?;
    let prior = spec.prior();
    for (name, marginal) in spec.param_names().iter().zip(prior.marginals()) {
        writeln!(out, "  parameter {name:<6} prior {marginal}")?;
    }
    let time = if matches!(named, NamedModel::Builtin(BuiltinModel::Benchmark)) {
        "discrete time, one sample per step".to_string()
    } else {
        format!("sampled every {} s", format_f64(spec.sample_time()))
    };
    writeln!(out, "  samples   N = {} ({time})", spec.n_samples())?;
    writeln!(
        out,
        "  signals   input {}, output {}",
        none_if_empty(&spec.input_names().join(",")),
        spec.output_names().join(",")
    )?;
    writeln!(out, "  input     {}", none_if_empty(spec.input_note()))?;
    writeln!(out, "  noise     {}", none_if_empty(spec.noise_note()))?;
    let presets = named.preset_names();
    writeln!(
        out,
        "  presets   {} (train --preset)",
        none_if_empty(&presets.join(", "))
    )?;
    let mut methods: Vec<&str> = match named {
        NamedModel::Builtin(model) => ModelProfile::of(*model)
            .classic_methods()
            .iter()
            .map(|m| m.name())
            .collect(),
        NamedModel::File(_) => Vec::new(),
    };
    // The output-error fit needs only a noise-free run on a given input.
    if named
        .simulator()
        .is_ok_and(|s| twostage::OutputError::new(s).is_ok())
    {
        methods.push("oe");
    }
    writeln!(
        out,
        "  methods   {} (estimate --method)",
        none_if_empty(&methods.join(", "))
    )?;
    writeln!(out)?;
    Ok(())
}

fn none_if_empty(text: &str) -> &str {
    if text.is_empty() { "none" } else { text }
}
