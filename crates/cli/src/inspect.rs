//! `twostage inspect`: what an estimator file holds, in words.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use twostage::{Estimator, FittedRegressor};

use crate::number::format_f64;

/// Run `twostage inspect FILE [--json]`.
pub fn inspect(path: &PathBuf, json: bool, out: &mut dyn Write) -> Result<()> {
    let e = Estimator::load(path)?;
    // The version the file was written in (it loaded, so the header is
    // whole): older files lack what later versions added.
    let version = std::fs::read(path)?
        .get(8..12)
        .and_then(|b| b.try_into().ok())
        .map_or(twostage::FORMAT_VERSION, u32::from_le_bytes);
    if json {
        let summary = serde_json::json!({
            "file": path.display().to_string(),
            "format_version": version,
            "training": e.training(),
            "parameters": e.param_names(),
            "lower": e.lower(),
            "upper": e.upper(),
            "priors": e.marginals(),
            "fixed": e.fixed(),
            "validation": e.validation(),
            "input_family": e.input_family().map(|f| f.describe(&e.signal_names().inputs)),
            "input_shapes": e.input_shapes().map(|s| serde_json::json!({
                "records": s.len(),
                "lags": twostage::models::SHAPE_LAGS,
                "threshold": s.threshold(),
            })),
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&summary)?)?;
        return Ok(());
    }
    let t = e.training();
    writeln!(
        out,
        "{}: twostage estimator file, format version {version}",
        path.display(),
    )?;
    writeln!(
        out,
        "  model       {} (trained by twostage {})",
        t.model, t.version
    )?;
    for (j, (name, marginal)) in e.param_names().iter().zip(e.marginals()).enumerate() {
        let range = format!(
            "[{}, {}]",
            format_f64(e.lower()[j]),
            format_f64(e.upper()[j])
        );
        if marginal.is_bounded() {
            writeln!(out, "  parameter   {name} in {range}, prior {marginal}")?;
        } else {
            writeln!(
                out,
                "  parameter   {name} in {range} (central 1 - 2e-6 of its prior {marginal})"
            )?;
        }
    }
    for held in e.fixed().values() {
        writeln!(
            out,
            "  fixed       {} = {} (held while training, not estimated)",
            held.name,
            format_f64(held.value)
        )?;
    }
    let shape = e.record_shape();
    writeln!(
        out,
        "  records     N = {}, sampled every {}",
        shape.n_samples,
        format_f64(shape.sample_time)
    )?;
    writeln!(out, "  stage 1     {}", e.compressor())?;
    let network = match e.regressor() {
        FittedRegressor::Mlp(net) => format!(
            "{}; layers {:?}, {} weights; trained by {}",
            t.regressor,
            net.sizes(),
            net.n_parameters(),
            net.training_summary()
        ),
        _ => t.regressor.to_string(),
    };
    writeln!(out, "  stage 2     {network}")?;
    if let Some(posterior) = e.posterior() {
        writeln!(out, "  posterior   {}", posterior.summary())?;
    }
    writeln!(
        out,
        "  training    m = {} records ({} failed), seed {}, {}",
        t.simulations,
        t.failures,
        t.seed,
        match t.records() {
            chart @ twostage::models::RecordsOrigin::Chart(_) => format!("from {chart}"),
            drawn => drawn.to_string(),
        }
    )?;
    match e.validation() {
        Some(report) => writeln!(out, "{report}")?,
        None => writeln!(out, "  not validated")?,
    }
    write!(out, "{}", trust_summary(&e))?;
    if let Some(block) = e.preset_block("again") {
        writeln!(
            out,
            "  to train this structure again, add to the model file (or give its compress and \
             fit):"
        )?;
        for line in block.lines() {
            writeln!(out, "    {line}")?;
        }
    }
    Ok(())
}

/// The adaptive intervals and the out-of-distribution envelope, in words.
pub(crate) fn trust_summary(e: &Estimator) -> String {
    let mut text = String::new();
    if let Some(a) = e.adaptive_intervals() {
        let _ = write!(
            text,
            "  adaptive {:.0}% intervals (normalized conformal, {} calibration records)",
            100.0 * (1.0 - a.alpha()),
            a.n_calibration()
        );
        if let (Some(widths), Some(coverage)) = (a.mean_half_width(), a.coverage()) {
            text.push_str(": ");
            let parts: Vec<String> = e
                .param_names()
                .iter()
                .zip(widths.iter().zip(coverage))
                .map(|(n, (w, c))| format!("{n} mean +-{w:.3e} (covers {:.1}%)", 100.0 * c))
                .collect();
            text.push_str(&parts.join(", "));
        }
        text.push('\n');
    }
    if let Some(envelope) = e.envelope() {
        let _ = writeln!(
            text,
            "  out of distribution beyond Mahalanobis distance {:.3} of the training features \
             (99.9% of them lie within)",
            envelope.threshold()
        );
    }
    if let Some(family) = e.input_family() {
        let _ = writeln!(
            text,
            "  input family of its {} held-out records (a record's input outside is out of \
             distribution, {:.0}% of each range's width of slack, at least {:.0}% of the number's \
             size, the mean's of the smallest RMS):",
            family.records(),
            100.0 * twostage::models::FAMILY_MARGIN,
            100.0 * twostage::models::FAMILY_MARGIN * twostage::models::FAMILY_LEAST_WIDTH
        );
        for line in family.describe(&e.signal_names().inputs) {
            let _ = writeln!(text, "    {line}");
        }
    }
    if let Some(shapes) = e.input_shapes() {
        let _ = writeln!(
            text,
            "  input shapes of {} held-out records (autocorrelations at lags {:?} samples): a \
             record's input beyond distance {:.3} of their nearest is out of distribution \
             ({:.0}% of theirs lie within)",
            shapes.len(),
            twostage::models::SHAPE_LAGS,
            shapes.threshold(),
            100.0 * twostage::models::SHAPE_LEVEL
        );
    }
    text
}
