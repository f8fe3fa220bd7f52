//! `twostage learning-curve`: validation RMSE against the number of
//! training simulations, so a user sees whether more would help.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use twostage::TwoStage;

use crate::model_arg::ModelArgs;
use crate::specs::{compressor, regressor};
use crate::usage;

/// Options of `twostage learning-curve`.
#[derive(Debug, clap::Args)]
pub struct CurveArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Stage 1 (as in `train`; default: the paper preset's).
    #[arg(long)]
    compress: Option<String>,
    /// Stage 2 (as in `train`; default: the paper preset's).
    #[arg(long)]
    fit: Option<String>,
    /// The smallest m; m doubles from here.
    #[arg(long, default_value_t = 250)]
    from: usize,
    /// The largest m.
    #[arg(long, default_value_t = 16000)]
    to: usize,
    /// Fresh validation simulations, the same for every m.
    #[arg(long, default_value_t = 1000)]
    validate: usize,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also draw the curve as SVG here.
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// Train at m = from, 2 from, ... up to `to`, validate each on the same
/// fresh simulations, and print one row per m as it finishes.
pub fn learning_curve(args: &CurveArgs, out: &mut dyn Write) -> Result<()> {
    let model = args.model.resolve()?;
    if args.from < 10 || args.to < args.from {
        return Err(usage(format!(
            "--from {} --to {}: need 10 <= from <= to",
            args.from, args.to
        )));
    }
    if args.validate == 0 {
        return Err(usage("--validate must be at least 1".into()));
    }
    let sim = model.simulator(false)?;
    let preset = model.preset(None)?;
    let stage1 = args.compress.as_deref().map(compressor).transpose()?;
    let stage2 = args.fit.as_deref().map(regressor).transpose()?;
    let names = sim.param_names().to_vec();
    write!(out, "m,seconds")?;
    for n in &names {
        write!(out, ",rmse_{n}")?;
    }
    writeln!(out)?;
    let mut sizes = Vec::new();
    let mut rmse: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut m = args.from;
    while m <= args.to {
        let mut builder = TwoStage::builder(sim.as_ref())
            .preset(preset.clone())
            .simulations(m)
            .seed(args.seed)
            .calibration(0)
            .validation(args.validate);
        if let Some(c) = &stage1 {
            builder = builder.compressor(c.clone());
        }
        if let Some(r) = &stage2 {
            builder = builder.regressor(r.clone());
        }
        let start = std::time::Instant::now();
        let estimator = builder
            .train()
            .with_context(|| format!("training with m = {m}"))?;
        let report = estimator
            .validation()
            .context("the estimator was not validated")?;
        write!(out, "{m},{:.2}", start.elapsed().as_secs_f64())?;
        for (j, p) in report.parameters.iter().enumerate() {
            write!(out, ",{:.6e}", p.rmse)?;
            rmse[j].push(p.rmse);
        }
        writeln!(out)?;
        out.flush()?;
        sizes.push(m);
        m = m.saturating_mul(2);
    }
    if let Some(path) = &args.plot {
        let curves: Vec<twostage_plot::Curve<'_>> = names
            .iter()
            .zip(&rmse)
            .map(|(name, r)| twostage_plot::Curve {
                name,
                simulations: &sizes,
                rmse: r,
                limit: None,
            })
            .collect();
        let title = format!(
            "Learning curve: {} ({} validation records)",
            model.name(),
            args.validate
        );
        let svg = twostage_plot::learning_curve(&title, &curves)?;
        twostage::write_whole(path, svg.as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
