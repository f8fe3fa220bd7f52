//! `twostage train`: simulate, compress, fit, calibrate and validate.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use twostage::models::FixedValues;
use twostage::{Budget, ChartDir, RecordsRequest, RunSettings, TrainingRequest};

use crate::OrUsage;
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
    /// itself, for records of tens of samples), linearized[:S] (the
    /// record regressed on the model's own output sensitivities at the
    /// prior's centre, S Runge-Kutta steps a sample; for the built-in car
    /// and model files of it), each after output
    /// transforms when written log+SPEC or log1p+SPEC (log,id+SPEC: one
    /// per output), and followed by +level (each output's first sample
    /// and mean) or +summary (each signal's mean, RMS, peak and mean
    /// frequency: for a family of inputs), and last by +learned[:C,C,..]
    /// (a convolutional summary network over every signal, trained with
    /// the estimator; learned alone uses it without other features)
    /// (default: the preset's). ARX orders apply to each of the model's
    /// inputs and outputs.
    #[arg(long)]
    compress: Option<String>,
    /// Stage 2: linear, mlp:H[,H...] hidden sizes, ensemble:H[,H...][xN]
    /// (the network's independently seeded restarts averaged: 4, or N),
    /// or piecewise:K,H
    /// (a global H-unit network routing to K experts by pieces of the first
    /// parameter's range) (default: the preset's).
    #[arg(long)]
    fit: Option<String>,
    /// Search compressors, output transforms and networks (and a learned
    /// stage 1, where the records' inputs differ in level or shape) by
    /// held-out error instead of using the preset (with --budget-seconds or
    /// --budget-sims; default 120 s). On a --chart the search fits and
    /// scores on the chart's training records, no new simulation (under a
    /// time budget on the first it affords, and the winner's final fit
    /// learns from them all). A model without presets searches even
    /// without --auto.
    #[arg(long, conflicts_with_all = ["compress", "fit", "sims"])]
    auto: bool,
    /// --auto: wall-clock seconds for the whole run (machine-dependent
    /// outcome): a pilot simulation times the model, the calibration and
    /// validation records (--calibrate, --validate) are reserved first,
    /// and a tenth for the validation's growth toward its certificate
    /// (--certify-within), the search and final fit get the rest. Where
    /// the reserve would take
    /// more than half the budget, both sets shrink alike to what half
    /// affords (at least 100 each, said in a note); a budget too small
    /// even for those is refused with the smallest budget it accepts.
    #[arg(long, requires = "auto", conflicts_with = "budget_sims")]
    budget_seconds: Option<f64>,
    /// --auto: simulations in the chart (with --chart: its first records),
    /// every candidate evaluated (reproducible outcome).
    #[arg(long, requires = "auto")]
    budget_sims: Option<usize>,
    /// Also train the posterior: a density of the parameters given stage
    /// 1's features, a mixture of K Gaussians with full covariances, that
    /// `estimate --samples` draws from. With --auto, K is the most: the
    /// count of 1, 2, 3, 5, 8 up to K of the lowest held-out negative
    /// log-likelihood is kept.
    #[arg(long, value_name = "K")]
    posterior: Option<usize>,
    /// Hold a parameter at a value, not estimated (NAME=VALUE,
    /// repeatable): the estimator is of the others, the model file
    /// unchanged, and every later check, refinement, joint fit and
    /// validation through the estimator holds it too. Simulated records
    /// only.
    #[arg(long, value_name = "NAME=VALUE")]
    fix: Vec<String>,
    /// Seed of every random choice (default 1; with shards, theirs).
    #[arg(long)]
    seed: Option<u64>,
    /// Fresh simulations for the validation report, exactly (0: none).
    /// Without it the validation starts with 1000 and grows until the
    /// certificate is within --certify-within of the observed error.
    #[arg(long)]
    validate: Option<usize>,
    /// Grow the validation (from --validate records, default 1000) until
    /// every certified RMSE is at most K times the observed one, each
    /// round as many records as the last predicts, at most
    /// --max-validate. The default, with K 1.2, where no --validate is
    /// given; records read from a chart or shards cannot grow, and the
    /// report says how many it would take.
    #[arg(long, value_name = "K")]
    certify_within: Option<f64>,
    /// The most validation records growing may take (default 1,000,000).
    #[arg(long, value_name = "M")]
    max_validate: Option<usize>,
    /// Fresh simulations for the conformal intervals (0: none; adaptive
    /// intervals need at least 100). With 4000 the coverage on fresh
    /// records stays within about 2 points of the level.
    #[arg(long, default_value_t = RunSettings::default().calibration)]
    calibrate: usize,
    /// Interval miscoverage: 0.1 gives 90% intervals, 0.05 95%.
    #[arg(long, default_value_t = RunSettings::default().alpha)]
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
    #[arg(long, value_name = "DIR", conflicts_with = "sims")]
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
    /// The report on stdout as text, or as JSON (what `inspect --format
    /// json` prints of the file written; the search's candidates and the
    /// timings stay on the text report).
    #[command(flatten)]
    format: crate::options::FormatArgs,
}

impl TrainArgs {
    /// The training request these options make.
    fn request(&self) -> Result<TrainingRequest> {
        let mut records = self
            .chart
            .as_ref()
            .map_or(RecordsRequest::Simulated, RecordsRequest::chart);
        if let RecordsRequest::Chart {
            calibration,
            validation,
            ..
        } = &mut records
        {
            *calibration = self.calibrate_chart.as_ref().map(ChartDir::new);
            *validation = self.validate_chart.as_ref().map(ChartDir::new);
        }
        let search =
            Budget::chosen(self.auto, self.budget_seconds, self.budget_sims).map_err(|e| {
                let flag = match (e, self.budget_seconds) {
                    (twostage::BudgetChoiceError::Both, _) => "--budget-seconds and --budget-sims",
                    (_, Some(_)) => "--budget-seconds",
                    (_, None) => "--budget-sims",
                };
                usage(format!("{flag}: {e}"))
            })?;
        Ok(TrainingRequest {
            preset: self.preset.clone(),
            simulations: self.sims,
            compress: self.compress.clone(),
            fit: self.fit.clone(),
            search,
            posterior: self.posterior,
            settings: RunSettings {
                seed: self.seed,
                calibration: self.calibrate,
                alpha: self.alpha,
                ..RunSettings::default()
            }
            .validation_asked(self.validate, self.certify_within, self.max_validate),
            records,
            fix: FixedValues::parse(&self.fix).map_err(|e| usage(format!("--fix: {e}")))?,
        })
    }
}

/// Run `twostage train`.
pub fn train(args: &TrainArgs, out: &mut dyn Write) -> Result<()> {
    let model = args.model.resolve()?;
    // Structures are named by their option when they do not parse.
    if let Some(spec) = &args.compress {
        compressor(spec)?;
    }
    if let Some(spec) = &args.fit {
        regressor(spec)?;
    }
    // Before the work: a training that ends unable to save is lost.
    twostage::check_writable(&args.out)?;
    let request = args.request()?;
    if !request.fix.is_empty() {
        // Before the work: a name the model does not have is a usage error.
        let described = model.named().chart_model()?;
        request
            .fix
            .positions(described.spec())
            .map_err(|e| usage(format!("--fix: {e}")))?;
    }
    if matches!(request.records, RecordsRequest::Shards { .. })
        && (args.validate_chart.is_some() || args.calibrate_chart.is_some())
    {
        return Err(usage(
            "shards hold their own calibration and validation records: leave out \
             --validate-chart and --calibrate-chart"
                .into(),
        ));
    }
    let searching = request.search_budget(model.named()).or_usage()?.is_some();
    if !args.quiet {
        eprintln!(
            "training the {} estimator ({})...",
            model.name(),
            request.steps(searching)
        );
    }
    let start = std::time::Instant::now();
    let bars = crate::bars::Bars::new(args.quiet);
    let trained = request.train(model.named(), &bars).map_err(|e| {
        // What was asked for is the user's to fix, like a bad flag.
        if e.is_setting() {
            usage(e.to_string())
        } else {
            anyhow::Error::new(e).context("training")
        }
    })?;
    let text = !args.quiet && !args.format.json();
    if let (Some(outcome), true) = (trained.search(), text) {
        writeln!(out, "{outcome}")?;
        if let Some(block) = outcome.estimator.preset_block("searched") {
            writeln!(
                out,
                "to train this design again without searching, add to the model file:\n{block}"
            )?;
        }
    }
    let estimator = trained.into_estimator();
    estimator.save(&args.out)?;
    if args.format.json() && !args.quiet {
        return crate::inspect::inspect(&args.out, true, out);
    }
    if text {
        let total = start.elapsed();
        writeln!(
            out,
            "trained in {:.3} s; wrote {}",
            total.as_secs_f64(),
            args.out.display()
        )?;
        let outside = if searching {
            "the design search's own work, starting the simulator, writing the file"
        } else {
            "starting the simulator, writing the file"
        };
        writeln!(out, "phases: {}", bars.phase_times(total, outside))?;
        if let Some(trained_by) = estimator.regressor().training_summary() {
            writeln!(out, "stage 2: {trained_by}")?;
        }
        if let chart @ twostage::models::RecordsOrigin::Chart(_) = estimator.training().records() {
            // The certificate covers records drawn as the chart's were.
            writeln!(out, "trained on {chart}")?;
        }
        if let Some(report) = estimator.validation() {
            writeln!(out, "{report}")?;
        }
        write!(out, "{}", trust_summary(&estimator))?;
    }
    Ok(())
}
