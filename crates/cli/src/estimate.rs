//! `twostage train`, `twostage inspect`, `twostage estimate`.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use twostage::compress::{Arx, Narx, OutputPca};
use twostage::fit::{MlpParams, Ridge};
use twostage::models::{BuiltinModel, IoData};
use twostage::{
    CompressorConfig, Estimator, FittedRegressor, ModelProfile, RegressorConfig, TwoStage,
};

use crate::number::format_f64;
use crate::{csv_records, usage};

/// Options of `twostage train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// The model: benchmark or pacejka.
    #[arg(long)]
    model: String,
    /// Start from a preset of the model's (`paper`, the default, is the
    /// paper's setting; `twostage models` lists each model's).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Training simulations m (default: the preset's).
    #[arg(long)]
    sims: Option<usize>,
    /// Stage 1: arx:NA,NB, narx:NA,NB,DEG or pca:K (output principal
    /// components; only for models whose experiments share one input)
    /// (default: the preset's).
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
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    seed: u64,
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
    /// Where to write the estimator.
    #[arg(long)]
    out: PathBuf,
    /// Print nothing but errors.
    #[arg(long)]
    quiet: bool,
}

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

/// Run `twostage train`.
pub fn train(args: &TrainArgs, out: &mut dyn Write) -> Result<()> {
    let model: BuiltinModel = args
        .model
        .parse()
        .map_err(|e| usage(format!("{e} (see `twostage models`)")))?;
    let sim = model.build(false)?;
    let preset = ModelProfile::of(model)
        .preset(&args.preset)
        .map_err(|e| usage(e.to_string()))?;
    let mut builder = TwoStage::builder(sim.as_ref())
        .preset(preset)
        .seed(args.seed)
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
    let estimator = if args.auto {
        let budget = match (args.budget_seconds, args.budget_sims) {
            (_, Some(m)) => twostage::Budget::Simulations(m),
            (Some(t), None) => twostage::Budget::Seconds(t),
            (None, None) => twostage::Budget::Seconds(120.0),
        };
        let outcome = TwoStage::auto(sim.as_ref())
            .budget(budget)
            .settings(|b| {
                b.seed(args.seed)
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
        if let Some(report) = estimator.validation() {
            writeln!(out, "{report}")?;
        }
        write!(out, "{}", trust_summary(&estimator))?;
    }
    Ok(())
}

/// Run `twostage inspect FILE`.
pub fn inspect(path: &PathBuf, out: &mut dyn Write) -> Result<()> {
    let e = Estimator::load(path)?;
    let t = e.training();
    writeln!(
        out,
        "{}: twostage estimator file, format version {}",
        path.display(),
        twostage::FORMAT_VERSION
    )?;
    writeln!(
        out,
        "  model       {} (trained by twostage {})",
        t.model, t.version
    )?;
    for (j, name) in e.param_names().iter().enumerate() {
        writeln!(
            out,
            "  parameter   {name} in [{}, {}]",
            format_f64(e.lower()[j]),
            format_f64(e.upper()[j])
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
            "{}; layers {:?}, {} weights, best restart stopped by {:?}",
            t.regressor,
            net.sizes(),
            net.n_parameters(),
            net.best_restart().reason
        ),
        _ => t.regressor.to_string(),
    };
    writeln!(out, "  stage 2     {network}")?;
    writeln!(
        out,
        "  training    m = {} simulations ({} failed), seed {}, {} design",
        t.simulations, t.failures, t.seed, t.sampling
    )?;
    match e.validation() {
        Some(report) => writeln!(out, "{report}")?,
        None => writeln!(out, "  not validated")?,
    }
    write!(out, "{}", trust_summary(&e))?;
    Ok(())
}

/// The adaptive intervals and the out-of-distribution envelope, in words.
fn trust_summary(e: &Estimator) -> String {
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
    text
}

/// Options of `twostage estimate`.
#[derive(Debug, clap::Args)]
pub struct EstimateArgs {
    /// The estimator file written by `twostage train`.
    #[arg(long, conflicts_with_all = ["model", "method"])]
    estimator: Option<PathBuf>,
    /// With --estimator of a built-in model: refine each estimate by the
    /// posterior mean of the prediction-error likelihood over twice its
    /// interval (about 1 ms per benchmark record, 0.4 s per car record).
    #[arg(long, requires = "estimator")]
    refine: bool,
    /// With --method: the model the records come from (benchmark or pacejka).
    #[arg(long, requires = "method")]
    model: Option<String>,
    /// A classic method instead of an estimator: ekf, ukf, pf, pem, ii
    /// (indirect inference through the TS preset's ARX) or bayes.
    #[arg(long, requires = "model")]
    method: Option<String>,
    /// EKF/UKF initial covariance: eq6 or eq7 (the paper's).
    #[arg(long, default_value = "eq6")]
    p0: String,
    /// Particle filter: number of particles (default 1000 benchmark, 500 car).
    #[arg(long)]
    particles: Option<usize>,
    /// Prediction error and indirect inference: number of random starts.
    #[arg(long, default_value_t = 5)]
    starts: usize,
    /// Seed of the random methods.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// CSV files: header u,y (one record) or experiment,u,y (many).
    #[arg(required = true)]
    data: Vec<PathBuf>,
    /// Output format: csv or json.
    #[arg(long, value_parser = ["csv", "json"], default_value = "csv")]
    format: String,
    /// Write the estimates here instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// One record's estimate, its interval half-widths and its feature
/// distance with the out-of-distribution threshold, where known.
struct Estimated {
    theta: Vec<f64>,
    widths: Option<Vec<f64>>,
    distance: Option<(f64, f64)>,
}

impl Estimated {
    fn out_of_distribution(&self) -> bool {
        self.distance.is_some_and(|(d, t)| d > t)
    }
}

/// Estimates one record, or says why it cannot.
type Method = Box<dyn FnMut(&IoData) -> Result<Estimated, String>>;

/// Refines a TS estimate of one record.
type Refine = Box<dyn FnMut(&IoData, &[f64]) -> Result<Vec<f64>, String>>;

/// The local posterior refinement for an estimator of a built-in model:
/// twice its 90% (or calibrated) interval, 45 points per axis for one
/// parameter, 13 for two.
fn refinement(estimator: &Estimator) -> Result<Refine> {
    use twostage_baselines as b;
    let model: BuiltinModel = estimator.training().model.parse().map_err(|_| {
        usage(format!(
            "--refine needs the likelihood of the model, known for the built-in models only; \
             this estimator is of '{}'",
            estimator.training().model
        ))
    })?;
    let radius: Vec<f64> = estimator
        .intervals()
        .ok_or_else(|| {
            usage("--refine sizes its neighbourhood by the estimator's intervals: train with --calibrate > 0".into())
        })?
        .half_widths()
        .iter()
        .map(|w| 2.0 * w)
        .collect();
    let points = ModelProfile::of(model).refinement_points();
    let pe = b::PredictionError::new(b::exact_likelihood(model)?, 1);
    Ok(Box::new(move |record: &IoData, start: &[f64]| {
        Ok(pe
            .local_posterior(record, start, &radius, points)
            .map_err(|e| e.to_string())?
            .mean)
    }))
}

/// The method chosen on the command line, ready to estimate records: the
/// parameter names, the method, and the record length an estimator file
/// was trained and validated on.
fn method(args: &EstimateArgs) -> Result<(Vec<String>, Method, Option<usize>)> {
    use twostage_baselines as b;
    if let Some(path) = &args.estimator {
        let estimator = Estimator::load(path)?;
        let names = estimator.param_names().to_vec();
        let trained = estimator.record_shape().n_samples;
        let mut refine = if args.refine {
            Some(refinement(&estimator)?)
        } else {
            None
        };
        return Ok((
            names,
            Box::new(move |record: &IoData| {
                let a = estimator.assess(record).map_err(|e| e.to_string())?;
                let theta = match refine.as_mut() {
                    Some(refine) => refine(record, &a.theta)?,
                    None => a.theta,
                };
                Ok(Estimated {
                    distance: a.feature_distance.zip(a.distance_threshold),
                    theta,
                    // The adaptive intervals have the same level and follow
                    // the record; the fixed ones are the fallback. Both were
                    // calibrated for the TS estimate, not a refined one.
                    widths: a.adaptive_half_widths.or(a.half_widths),
                })
            }),
            Some(trained),
        ));
    }
    let (Some(model), Some(name)) = (&args.model, &args.method) else {
        return Err(usage(
            "give --estimator FILE, or --model M --method ekf|ukf|pf|pem|ii|bayes".into(),
        ));
    };
    let model: BuiltinModel = model.parse().map_err(|e| usage(format!("{e}")))?;
    let names = model.build(false)?.param_names().to_vec();
    let initial_covariance = match args.p0.as_str() {
        "eq6" => b::InitialCovariance::Eq6,
        "eq7" => b::InitialCovariance::Eq7,
        other => return Err(usage(format!("--p0 '{other}': use eq6 or eq7"))),
    };
    let method = ModelProfile::of(model)
        .classic_method(name)
        .map_err(|e| usage(e.to_string()))?;
    let settings = b::MethodSettings {
        initial_covariance,
        particles: args.particles,
        starts: args.starts,
        seed: args.seed,
    };
    let estimator = b::classic_estimator(model, method, &settings)?;
    Ok((
        names,
        Box::new(move |record: &IoData| {
            estimator
                .estimate(record)
                .map(|e| Estimated {
                    theta: e.theta,
                    widths: None,
                    distance: None,
                })
                .map_err(|e| e.to_string())
        }),
        None,
    ))
}

/// Run `twostage estimate`; returns how many records failed.
pub fn estimate(args: &EstimateArgs) -> Result<usize> {
    let (names, mut estimate_one, trained_samples) = method(args)?;
    let mut rows: Vec<(String, Estimated)> = Vec::new();
    let mut failed = 0;
    for path in &args.data {
        for read in csv_records::read(path).map_err(|e| anyhow::anyhow!(e))? {
            let outcome = read.record.and_then(|record| {
                let n = record.n_samples();
                match trained_samples {
                    // The estimate is still defined, but the validation
                    // error and the intervals were measured for another N.
                    Some(trained) if n != trained => eprintln!(
                        "warning: {}: experiment {}: {n} samples, the estimator was trained \
                         and validated on N = {trained}; its accuracy and intervals may not hold",
                        path.display(),
                        read.id
                    ),
                    _ => {}
                }
                estimate_one(&record)
                    .map_err(|e| format!("{}: experiment {}: {e}", path.display(), read.id))
            });
            match outcome {
                Ok(estimated) => {
                    if let Some((d, t)) = estimated.distance.filter(|(d, t)| d > t) {
                        eprintln!(
                            "warning: {}: experiment {}: out of distribution: its features lie \
                             at Mahalanobis distance {d:.3} from the training features, beyond \
                             the {t:.3} that 99.9% of them stay within; the estimate extrapolates \
                             and the intervals do not cover it (is it the same model and input?)",
                            path.display(),
                            read.id
                        );
                    }
                    rows.push((read.id, estimated));
                }
                Err(problem) => {
                    failed += 1;
                    eprintln!("error: {problem}");
                }
            }
        }
    }
    let text = if args.format == "json" {
        json(&names, &rows)?
    } else {
        csv(&names, &rows)?
    };
    match &args.out {
        Some(path) => {
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?
        }
        None => std::io::stdout().lock().write_all(text.as_bytes())?,
    }
    Ok(failed)
}

fn csv(names: &[String], rows: &[(String, Estimated)]) -> Result<String> {
    let with_intervals = rows.iter().any(|(_, e)| e.widths.is_some());
    let with_distance = rows.iter().any(|(_, e)| e.distance.is_some());
    let mut text = String::from("experiment");
    for n in names {
        write!(text, ",{n}")?;
    }
    if with_intervals {
        for n in names {
            write!(text, ",{n}_lo,{n}_hi")?;
        }
    }
    if with_distance {
        text.push_str(",feature_distance,out_of_distribution");
    }
    text.push('\n');
    for (id, e) in rows {
        write!(text, "{id}")?;
        for t in &e.theta {
            write!(text, ",{}", format_f64(*t))?;
        }
        if let Some(widths) = &e.widths {
            for (t, w) in e.theta.iter().zip(widths) {
                write!(text, ",{},{}", format_f64(t - w), format_f64(t + w))?;
            }
        }
        if let Some((d, _)) = e.distance {
            write!(text, ",{},{}", format_f64(d), e.out_of_distribution())?;
        }
        text.push('\n');
    }
    Ok(text)
}

fn json(names: &[String], rows: &[(String, Estimated)]) -> Result<String> {
    let records: Vec<serde_json::Value> = rows
        .iter()
        .map(|(id, e)| {
            let mut object = serde_json::Map::new();
            object.insert("experiment".into(), id.clone().into());
            for (j, n) in names.iter().enumerate() {
                object.insert(n.clone(), e.theta[j].into());
                if let Some(w) = &e.widths {
                    object.insert(format!("{n}_lo"), (e.theta[j] - w[j]).into());
                    object.insert(format!("{n}_hi"), (e.theta[j] + w[j]).into());
                }
            }
            if let Some((d, _)) = e.distance {
                object.insert("feature_distance".into(), d.into());
                object.insert("out_of_distribution".into(), e.out_of_distribution().into());
            }
            serde_json::Value::Object(object)
        })
        .collect();
    Ok(serde_json::to_string_pretty(&records)? + "\n")
}
