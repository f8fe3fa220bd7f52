//! The stage-1 and stage-2 specifications the commands take: `arx:NA,NB`,
//! `narx:NA,NB,DEG`, `pca:K`; `linear`, `mlp:H[,H...]`, `piecewise:K,H`.

use anyhow::Result;
use twostage::compress::{Arx, Narx, OutputPca};
use twostage::fit::{MlpParams, Ridge};
use twostage::{CompressorConfig, RegressorConfig};

use crate::usage;

fn parse_counts(spec: &str, what: &str, count: usize) -> Result<Vec<usize>> {
    let values: Vec<usize> = spec
        .split(',')
        .map(|v| v.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            usage(format!(
                "{what}: '{spec}' must be {count} whole numbers separated by commas"
            ))
        })?;
    if values.len() != count {
        return Err(usage(format!(
            "{what}: '{spec}' must be {count} whole numbers separated by commas"
        )));
    }
    Ok(values)
}

pub(crate) fn compressor(spec: &str) -> Result<CompressorConfig> {
    let bad = || {
        usage(format!(
            "--compress '{spec}': use arx:NA,NB, narx:NA,NB,DEG or pca:K"
        ))
    };
    let (kind, orders) = spec.split_once(':').ok_or_else(bad)?;
    match kind {
        "arx" => {
            let o = parse_counts(orders, "--compress arx", 2)?;
            Ok(Arx::new(o[0], o[1])
                .map_err(|e| usage(format!("--compress: {e}")))?
                .into())
        }
        "narx" => {
            let o = parse_counts(orders, "--compress narx", 3)?;
            Ok(Narx::new(o[0], o[1], o[2])
                .map_err(|e| usage(format!("--compress: {e}")))?
                .into())
        }
        "pca" => {
            let k = parse_counts(orders, "--compress pca", 1)?;
            Ok(OutputPca::new(k[0])
                .map_err(|e| usage(format!("--compress: {e}")))?
                .into())
        }
        _ => Err(bad()),
    }
}

pub(crate) fn regressor(spec: &str) -> Result<RegressorConfig> {
    if spec == "linear" {
        return Ok(RegressorConfig::Linear(Ridge::default()));
    }
    if let Some(rest) = spec.strip_prefix("piecewise:") {
        let counts = parse_counts(rest, "--fit piecewise", 2)?;
        let mlp = MlpParams::new(&[counts[1]])
            .and_then(MlpParams::check)
            .map_err(|e| usage(format!("--fit: {e}")))?;
        let pieces = twostage::fit::Piecewise::new(mlp.clone(), mlp, counts[0])
            .map_err(|e| usage(format!("--fit: {e}")))?;
        return Ok(RegressorConfig::Piecewise(pieces));
    }
    let hidden = spec.strip_prefix("mlp:").ok_or_else(|| {
        usage(format!(
            "--fit '{spec}': use linear, mlp:H[,H...] or piecewise:PIECES,H"
        ))
    })?;
    let sizes: Vec<usize> = hidden
        .split(',')
        .map(|h| h.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            usage(format!(
                "--fit '{spec}': hidden sizes must be whole numbers"
            ))
        })?;
    let mlp = MlpParams::new(&sizes)?
        .check()
        .map_err(|e| usage(format!("--fit: {e}")))?;
    Ok(RegressorConfig::Mlp(mlp))
}
