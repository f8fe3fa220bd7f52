//! The stage-1 and stage-2 specifications the commands take (`arx:NA,NB`,
//! `mlp:H`, ...; parsed by the facade, as model files write them too), with
//! the option's name in the message.

use anyhow::Result;
use twostage::{CompressorConfig, RegressorConfig};

use crate::OrUsage;

pub(crate) fn compressor(spec: &str) -> Result<CompressorConfig> {
    spec.parse().usage_context("--compress")
}

pub(crate) fn regressor(spec: &str) -> Result<RegressorConfig> {
    spec.parse().usage_context("--fit")
}
