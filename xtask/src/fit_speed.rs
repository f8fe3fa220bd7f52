//! What the stage-2 fit costs and buys, apart from everything else a
//! training run does: a model's training and validation charts are
//! simulated and compressed once, then the fit alone is timed, and its
//! RMSE per parameter on the validation chart is reported in the space the
//! network learns in (logarithms for log-normal parameters). The charts
//! can be written out as CSV so that another tool (scikit-learn) fits the
//! very same features.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use ndarray::{Array2, ArrayView2};
use twostage::estimator::space::to_learning_space;
use twostage::fit::{FittedRegressor, Predictor};
use twostage::sources::ForModel;
use twostage::{CompressorConfig, NamedModel, RegressorConfig, compress_chart};

/// The charts of one model, compressed, in the network's target space.
struct Charts {
    train: (Array2<f64>, Array2<f64>),
    validation: (Array2<f64>, Array2<f64>),
}

fn charts(
    model: &NamedModel,
    compress: &str,
    sims: usize,
    validate: usize,
    seed: u64,
) -> Result<Charts> {
    let simulator = model.simulator()?;
    let spec = simulator.spec();
    let compressor: CompressorConfig = compress
        .parse()
        .with_context(|| format!("--compress {compress}"))?;
    let compressor = compressor.for_model(spec)?;
    let chart = |m: usize, seed: u64| -> Result<(Array2<f64>, Array2<f64>)> {
        let design = spec.prior().design(m, seed)?;
        let chart = compress_chart(simulator.as_ref(), &compressor, &design, "fit-speed", 0.05)?;
        let targets = to_learning_space(chart.thetas.view(), spec.prior().marginals());
        Ok((chart.features, targets))
    };
    Ok(Charts {
        train: chart(sims, seed)?,
        validation: chart(validate, seed.wrapping_add(0x5eed))?,
    })
}

/// Root mean squared error of each column.
fn rmse(predicted: ArrayView2<'_, f64>, truth: ArrayView2<'_, f64>) -> Vec<f64> {
    (0..truth.ncols())
        .map(|j| {
            let sum: f64 = predicted
                .column(j)
                .iter()
                .zip(truth.column(j))
                .map(|(p, t)| (p - t) * (p - t))
                .sum();
            (sum / truth.nrows().max(1) as f64).sqrt()
        })
        .collect()
}

fn write_csv(path: &Path, values: ArrayView2<'_, f64>) -> Result<()> {
    let mut text = String::new();
    for row in values.rows() {
        let cells: Vec<String> = row.iter().map(|v| format!("{v:e}")).collect();
        let _ = writeln!(text, "{}", cells.join(","));
    }
    fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// Options of `cargo xtask fit-speed`.
pub(crate) struct FitSpeed<'a> {
    pub(crate) model: &'a str,
    pub(crate) compress: &'a str,
    pub(crate) fit: &'a str,
    pub(crate) sims: usize,
    pub(crate) validate: usize,
    pub(crate) seed: u64,
    pub(crate) repeats: usize,
    pub(crate) export: Option<&'a Path>,
    /// A network's trainer instead of the structure's own: `lm`, `adam`
    /// or `lbfgs:N` (at most N iterations).
    pub(crate) trainer: Option<&'a str>,
    /// Fit on this many training records first, then further on all.
    pub(crate) first_rows: Option<usize>,
}

/// The trainer `--trainer` names.
fn trainer(name: &str) -> Result<twostage::fit::Trainer> {
    use twostage::fit::Trainer;
    Ok(match name.split_once(':') {
        None if name == "lm" => Trainer::LevenbergMarquardt,
        None if name == "adam" => Trainer::ADAM,
        Some(("lbfgs", n)) => Trainer::Lbfgs {
            iterations: n.parse().with_context(|| format!("--trainer {name}"))?,
        },
        _ => anyhow::bail!("--trainer {name}: give lm, adam or lbfgs:N"),
    })
}

pub(crate) fn run(options: &FitSpeed<'_>) -> Result<()> {
    let model = if Path::new(options.model).exists() {
        NamedModel::file(options.model)?
    } else {
        NamedModel::builtin(options.model)?
    };
    let start = Instant::now();
    let charts = charts(
        &model,
        options.compress,
        options.sims,
        options.validate,
        options.seed,
    )?;
    println!(
        "{}: {} training and {} validation records compressed by {} to {} features in {:.2} s",
        model.name(),
        charts.train.0.nrows(),
        charts.validation.0.nrows(),
        options.compress,
        charts.train.0.ncols(),
        start.elapsed().as_secs_f64()
    );
    if let Some(dir) = options.export {
        fs::create_dir_all(dir)?;
        write_csv(&dir.join("train_features.csv"), charts.train.0.view())?;
        write_csv(&dir.join("train_targets.csv"), charts.train.1.view())?;
        write_csv(
            &dir.join("validation_features.csv"),
            charts.validation.0.view(),
        )?;
        write_csv(
            &dir.join("validation_targets.csv"),
            charts.validation.1.view(),
        )?;
        println!("charts written to {}", dir.display());
    }
    let mut regressor: RegressorConfig = options
        .fit
        .parse()
        .with_context(|| format!("--fit {}", options.fit))?;
    let names = model.simulator()?.spec().param_names().to_vec();
    let own = regressor.clone();
    if let Some(name) = options.trainer {
        let RegressorConfig::Mlp(mlp) = &regressor else {
            anyhow::bail!("--trainer {name}: --fit {} is not a network", options.fit);
        };
        regressor = RegressorConfig::Mlp(mlp.params().clone().trainer(trainer(name)?).check()?);
    }
    if let Some(rows) = options.first_rows {
        return two_phases(options, (&charts, &names), &own, &regressor, rows);
    }
    let mut times = Vec::new();
    let mut fitted = None;
    for _ in 0..options.repeats.max(1) {
        let start = Instant::now();
        let fit = regressor.fit(charts.train.0.view(), charts.train.1.view(), options.seed)?;
        times.push(start.elapsed().as_secs_f64());
        fitted = Some(fit);
    }
    times.sort_by(f64::total_cmp);
    let Some(fitted) = fitted else {
        return Ok(());
    };
    println!(
        "fit {}: median {:.2} s of {} (from {:.2} to {:.2} s)",
        options.fit,
        times[times.len() / 2],
        times.len(),
        times[0],
        times[times.len() - 1]
    );
    print_restarts(&fitted);
    println!(
        "validation RMSE (learning space): {}",
        scored(&fitted, &charts, &names)?
    );
    Ok(())
}

/// `--first-rows`: `first` on the first `rows` training records, then
/// `further` from that fit on all of them, each phase timed and scored.
fn two_phases(
    options: &FitSpeed<'_>,
    (charts, names): (&Charts, &[String]),
    first: &RegressorConfig,
    further: &RegressorConfig,
    rows: usize,
) -> Result<()> {
    let (x, y) = (charts.train.0.view(), charts.train.1.view());
    let rows = rows.min(x.nrows());
    let part = ndarray::s![..rows, ..];
    let start = Instant::now();
    let begun = first.fit(x.slice(part), y.slice(part), options.seed)?;
    let first_seconds = start.elapsed().as_secs_f64();
    let score = |fitted: &FittedRegressor| scored(fitted, charts, names);
    println!(
        "phase 1: {} on {rows} records, {first_seconds:.2} s, validation RMSE {}",
        options.fit,
        score(&begun)?
    );
    let start = Instant::now();
    let ended = further.fit_from(Some(&begun), (x, y), options.seed, None)?;
    let further_seconds = start.elapsed().as_secs_f64();
    print_restarts(&ended);
    println!(
        "phase 2: further on {} records, {further_seconds:.2} s, validation RMSE {}",
        x.nrows(),
        score(&ended)?
    );
    Ok(())
}

/// A network's restarts (or members trained further): iterations, why
/// each stopped, held-out error.
fn print_restarts(fitted: &FittedRegressor) {
    if let FittedRegressor::Mlp(mlp) = fitted {
        for report in mlp.reports() {
            println!(
                "  restart {}: {} iterations, {}, held-out MSE {:.4e}",
                report.restart,
                report.iterations,
                report.reason.name(),
                report.validation_mse
            );
        }
    }
}

/// `fitted`'s validation RMSE per parameter (`name value`, in the space
/// the network learns in).
fn scored(fitted: &FittedRegressor, charts: &Charts, names: &[String]) -> Result<String> {
    let predicted = fitted.predict(charts.validation.0.view())?;
    let errors = rmse(predicted.view(), charts.validation.1.view());
    Ok(names
        .iter()
        .zip(&errors)
        .map(|(name, e)| format!("{name} {e:.4e}"))
        .collect::<Vec<_>>()
        .join(", "))
}
