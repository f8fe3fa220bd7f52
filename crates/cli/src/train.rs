//! `twostage train`: simulate, compress, fit, calibrate and validate.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use twostage::{ChartFiles, TwoStage};

use crate::inspect::trust_summary;
use crate::model_arg::ModelArgs;
use crate::specs::{compressor, regressor};
use crate::usage;

/// Options of `twostage train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Start from a preset of the model's (default: a built-in model's
    /// `paper`, the paper's setting; `recommended` is what the automatic
    /// design chose, nearer the Bayes limit; a model file's first preset).
    #[arg(long)]
    preset: Option<String>,
    /// Training simulations m (default: the preset's).
    #[arg(long)]
    sims: Option<usize>,
    /// Stage 1: arx:NA,NB, ar:NA (outputs only, for a model without
    /// input), narx:NA,NB,DEG, pca:K (output principal components; only
    /// for models whose experiments share one input) or raw (the record
    /// itself, for records of tens of samples) (default: the preset's).
    /// ARX orders apply to each of the model's inputs and outputs.
    #[arg(long)]
    compress: Option<String>,
    /// Stage 2: linear, mlp:H[,H...] hidden sizes, or piecewise:K,H (a
    /// global H-unit network routing to K experts by pieces of the first
    /// parameter's range) (default: the preset's).
    #[arg(long)]
    fit: Option<String>,
    /// Search compressors and networks by held-out error instead of using
    /// the preset (with --budget-seconds or --budget-sims; default 120 s).
    #[arg(long, conflicts_with_all = ["compress", "fit", "sims"])]
    auto: bool,
    /// --auto: wall-clock seconds for the search (machine-dependent outcome).
    #[arg(long, requires = "auto", conflicts_with = "budget_sims")]
    budget_seconds: Option<f64>,
    /// --auto: simulations in the chart, every candidate evaluated
    /// (reproducible outcome).
    #[arg(long, requires = "auto")]
    budget_sims: Option<usize>,
    /// Seed of every random choice (default 1; with shards, theirs).
    #[arg(long)]
    seed: Option<u64>,
    /// Fresh simulations for the validation report (0: none).
    #[arg(long, default_value_t = 1000)]
    validate: usize,
    /// Fresh simulations for the conformal intervals (0: none; adaptive
    /// intervals need at least 100). With 4000 the coverage on fresh
    /// records stays within about 2 points of the level.
    #[arg(long, default_value_t = 4000)]
    calibrate: usize,
    /// Interval miscoverage: 0.1 gives 90% intervals, 0.05 95%.
    #[arg(long, default_value_t = 0.1)]
    alpha: f64,
    /// Train on a chart simulated elsewhere: a folder with truth.csv
    /// (experiment,<parameters>) and data.csv (experiment,<inputs>,<outputs>),
    /// as `twostage simulate --count --out-dir` writes, or theta.npy,
    /// inputs.npy and outputs.npy (float64 [m, q], [m, N, n_u], [m, N, n_y]). Without
    /// --validate-chart / --calibrate-chart, --validate and --calibrate
    /// records are held out of it at random. Or shard files of `simulate
    /// --shard` (a pattern such as 'DIR/shard-*', quoted): their training,
    /// calibration and validation records, seed and sizes, merged into the
    /// estimator a single machine would train (docs/cluster.md).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["auto", "sims"])]
    chart: Option<PathBuf>,
    /// With --chart: validate on this chart instead of held-out records.
    #[arg(long, value_name = "DIR", requires = "chart")]
    validate_chart: Option<PathBuf>,
    /// With --chart: calibrate the intervals on this chart instead of
    /// held-out records.
    #[arg(long, value_name = "DIR", requires = "chart")]
    calibrate_chart: Option<PathBuf>,
    /// Where to write the estimator.
    #[arg(long)]
    out: PathBuf,
    /// Print nothing but errors.
    #[arg(long)]
    quiet: bool,
}

/// The seed when none is given.
const DEFAULT_SEED: u64 = 1;

/// Whether `--chart` names shard files rather than a chart folder.
fn is_shard_pattern(chart: &std::path::Path) -> bool {
    let text = chart.to_string_lossy();
    text.contains(['*', '?', '[']) || text.ends_with(".tsshard")
}

/// Run `twostage train`.
pub fn train(args: &TrainArgs, out: &mut dyn Write) -> Result<()> {
    let model = args.model.resolve()?;
    let sim = if args.chart.is_some() {
        model.chart_model()?
    } else {
        model.simulator(false)?
    };
    let preset = model.preset(args.preset.as_deref())?;
    let mut builder = TwoStage::builder(sim.as_ref())
        .preset(preset)
        .seed(args.seed.unwrap_or(DEFAULT_SEED))
        .validation(args.validate)
        .calibration(args.calibrate)
        .alpha(args.alpha);
    if let Some(m) = args.sims {
        builder = builder.simulations(m);
    }
    if let Some(spec) = &args.compress {
        builder = builder.compressor(compressor(spec)?);
    }
    if let Some(spec) = &args.fit {
        builder = builder.regressor(regressor(spec)?);
    }
    if !args.quiet {
        eprintln!(
            "training the {} estimator (simulate, compress, fit, calibrate, validate)...",
            model.name()
        );
    }
    let start = std::time::Instant::now();
    let bars = crate::bars::Bars::new(args.quiet);
    let failed = |e: twostage::Error| match e {
        // A setting out of range is the user's to fix, like a bad flag.
        twostage::Error::InvalidSetting { .. } => usage(e.to_string()),
        other => anyhow::Error::new(other).context("training"),
    };
    let chart = |dir: &Option<PathBuf>| -> Result<Option<ChartFiles>> {
        dir.as_ref()
            .map(|d| ChartFiles::open(d, sim.spec()).map_err(|e| usage(e.to_string())))
            .transpose()
    };
    let shards = args
        .chart
        .as_ref()
        .filter(|c| is_shard_pattern(c))
        .map(|pattern| -> Result<twostage::ShardedChart> {
            if args.validate_chart.is_some() || args.calibrate_chart.is_some() {
                return Err(usage(
                    "shards hold their own calibration and validation records: leave out \
                     --validate-chart and --calibrate-chart"
                        .into(),
                ));
            }
            let chart = twostage::ShardedChart::open(&pattern.to_string_lossy())
                .map_err(|e| usage(e.to_string()))?;
            if chart.plan().model_fingerprint != model.fingerprint() {
                return Err(usage(format!(
                    "{}: the shards were simulated from another model description than {} \
                     (another model file, or this one since edited): simulate them again, or \
                     train with the model they came from",
                    chart.pattern(),
                    model.name()
                )));
            }
            Ok(chart)
        })
        .transpose()?;
    let estimator = if let Some(shards) = &shards {
        let plan = shards.plan();
        if !args.quiet {
            eprintln!(
                "merging {} shards: {} training, {} calibration and {} validation records, seed {}",
                shards.files().len(),
                plan.counts[0],
                plan.counts[1],
                plan.counts[2],
                plan.seed
            );
        }
        builder
            .seed(args.seed.unwrap_or(plan.seed))
            .progress(&bars)
            .train_on_shards(shards)
            .map_err(|e| match e {
                twostage::Error::Shards { .. } => usage(e.to_string()),
                other => failed(other),
            })?
    } else if let Some(training) = chart(&args.chart)? {
        let (calibration, validation) =
            (chart(&args.calibrate_chart)?, chart(&args.validate_chart)?);
        builder
            .progress(&bars)
            .train_on_chart(&training, calibration.as_ref(), validation.as_ref())
            .map_err(|e| match e {
                twostage::Error::ChartFile { .. } => usage(e.to_string()),
                other => failed(other),
            })?
    } else if args.auto {
        let budget = match (args.budget_seconds, args.budget_sims) {
            (_, Some(m)) => twostage::Budget::Simulations(m),
            (Some(t), None) => twostage::Budget::Seconds(t),
            (None, None) => twostage::Budget::Seconds(120.0),
        };
        let outcome = TwoStage::auto(sim.as_ref())
            .budget(budget)
            .settings(|b| {
                b.seed(args.seed.unwrap_or(DEFAULT_SEED))
                    .validation(args.validate)
                    .calibration(args.calibrate)
                    .alpha(args.alpha)
                    .progress(&bars)
            })
            .run()
            .map_err(failed)?;
        if !args.quiet {
            writeln!(out, "{outcome}")?;
        }
        outcome.estimator
    } else {
        builder.progress(&bars).train().map_err(failed)?
    };
    estimator.save(&args.out)?;
    if !args.quiet {
        writeln!(
            out,
            "trained in {:.2} s; wrote {}",
            start.elapsed().as_secs_f64(),
            args.out.display()
        )?;
        writeln!(out, "phases: {}", bars.phase_times())?;
        let sampling = &estimator.training().sampling;
        if sampling.starts_with("the chart") {
            // The certificate covers records drawn as the chart's were.
            writeln!(out, "trained on {sampling}")?;
        }
        if let Some(report) = estimator.validation() {
            writeln!(out, "{report}")?;
        }
        write!(out, "{}", trust_summary(&estimator))?;
    }
    Ok(())
}
