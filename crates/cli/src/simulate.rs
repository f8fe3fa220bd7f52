//! `twostage models` and `twostage simulate`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use twostage::Progress;
use twostage::RunSettings;
use twostage::models::{Simulator, experiment_rng};
use twostage::sources::chart_writer::push_record_rows;
use twostage::sources::csv_rows::row;
use twostage::sources::readable_bytes;
use twostage::sources::record_file::RecordFormat;
use twostage::sources::write_csv_chart;

use crate::OrUsage;
use crate::model_arg::ModelArgs;
use crate::number::{four_digits, parse_list};
use crate::{predict, usage};

/// Options of `twostage simulate`, already parsed by clap.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Parameter vector, comma separated (e.g. `--theta -35,-1.1`); one experiment.
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["count", "out_dir"])]
    theta: Option<String>,
    /// Seed of the random streams (input, noise, and drawn parameters)
    /// (default 0; with --shard, the training run's default, 1, as `train`).
    #[arg(long)]
    seed: Option<u64>,
    /// With --theta: which experiment's random stream to use, so that
    /// experiment I of a `--count` run can be simulated again alone.
    #[arg(long, default_value_t = 0, requires = "theta")]
    experiment: u64,
    /// Simulate without noise: the model's own response (built-in models,
    /// FMUs with their noise inputs at zero, commands speaking protocol 2;
    /// a model file's measurement noise is left out too).
    #[arg(long)]
    noiseless: bool,
    /// Accept a --theta, or --at values, outside the model's prior box.
    #[arg(long)]
    allow_outside_prior: bool,
    /// With --theta: write the CSV here instead of standard output. With
    /// --shard: the folder that receives the shard file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Simulate this many experiments with parameters drawn from the prior
    /// (with --shard: the training chart's size, as `train --sims`).
    #[arg(long)]
    count: Option<usize>,
    /// Simulate one shard of a training run's charts: I/N (from 0), or
    /// `auto` (Slurm's SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT), or
    /// `auto/N` (the index from SLURM_ARRAY_TASK_ID or Kubernetes'
    /// JOB_COMPLETION_INDEX). Needs --count and --out DIR; `train --chart
    /// 'DIR/shard-*'` merges the shards (docs/cluster.md).
    #[arg(long, value_name = "I/N", requires = "count", conflicts_with_all = ["theta", "out_dir"])]
    shard: Option<String>,
    /// With --shard: the validation chart's size (as `train --validate`).
    #[arg(long, default_value_t = RunSettings::default().validation, requires = "shard")]
    validate: usize,
    /// With --shard: the calibration chart's size (as `train --calibrate`).
    #[arg(long, default_value_t = RunSettings::default().calibration, requires = "shard")]
    calibrate: usize,
    /// With --shard: store features of this stage-1 compressor (arx:NA,NB,
    /// ar:NA or raw) instead of raw records, O(n) numbers per record.
    #[arg(long, requires = "shard")]
    compress: Option<String>,
    /// With --count: the folder that receives data.csv and truth.csv.
    #[arg(long, requires = "count")]
    out_dir: Option<PathBuf>,
    /// Simulate at each row of this estimate CSV (as `twostage estimate`
    /// writes it: `experiment` and one column per parameter), one
    /// experiment per row, to predict or to compare with a record; the
    /// CSV goes to --out or standard output.
    #[arg(long, value_name = "ESTIMATES.csv", conflicts_with_all = ["theta", "count", "shard"])]
    at: Option<PathBuf>,
    /// With --at: apply the inputs of this record CSV (the model's signal
    /// columns; one record for every row, or one per experiment id of the
    /// estimates) instead of the model's own input design.
    #[arg(long, value_name = "RECORD.csv", requires = "at")]
    input: Option<PathBuf>,
    /// With --input and --at a file of posterior draws (`estimate --samples
    /// N --draws FILE`: many rows of one experiment): write, per
    /// experiment and sample, each output's mean over the draws'
    /// simulations and their central band of this level in percent
    /// (`y_mean`, `y_low`, `y_high`), a prediction band, instead of every
    /// simulation; the band is scored against the record's outputs.
    #[arg(long, value_name = "PERCENT", requires = "input")]
    band: Option<f64>,
    /// With --input: score the prediction from this sample on (counted
    /// from 0), leaving out the first samples of a transient; the CSV still
    /// holds every sample.
    #[arg(long, value_name = "K", requires = "input")]
    score_from: Option<usize>,
    /// With --input: score the prediction up to this sample, not
    /// including it (counted from 0; default the record's end).
    #[arg(long, value_name = "K", requires = "input")]
    score_to: Option<usize>,
    /// With --input: before predicting a record, fit its own parameters
    /// (`per_record = true` in the model file: an initial state, a
    /// sensor offset) to its first K samples by output error, the others
    /// held at the row's values, as MATLAB's findstates; the prediction
    /// of the rest is then of the plant alone (score it with
    /// --score-from K).
    #[arg(long, value_name = "K", requires = "input")]
    own_from_first: Option<usize>,
}

/// Run `twostage simulate`.
pub fn simulate(args: &SimulateArgs) -> Result<()> {
    let model = args.model.resolve()?;
    let sim = model.simulator(args.noiseless)?;
    if let (Some(shard), Some(count)) = (&args.shard, args.count) {
        return one_shard(&model, sim.as_ref(), shard, count, args);
    }
    if args.out.is_some() && args.theta.is_none() && args.at.is_none() {
        return Err(usage(
            "--out goes with --theta (a CSV file) or --shard (a folder); --count writes to \
             --out-dir"
                .into(),
        ));
    }
    if args.allow_outside_prior && args.theta.is_none() && args.at.is_none() {
        return Err(usage(
            "--allow-outside-prior goes with --theta or --at, the values given; draws from the \
             prior (--count) lie in it"
                .into(),
        ));
    }
    if let Some(at) = &args.at {
        return at_estimates(sim.as_ref(), at, args);
    }
    match (&args.theta, args.count, &args.out_dir) {
        (Some(theta), None, None) => one_experiment(sim.as_ref(), theta, args),
        (None, Some(count), Some(dir)) => {
            many_experiments(sim.as_ref(), count, args.seed.unwrap_or(0), dir)
        }
        _ => Err(usage(
            "give either --theta V[,V...] for one experiment, or --count M --out-dir DIR \
             for M experiments drawn from the prior"
                .into(),
        )),
    }
}

fn one_experiment(sim: &dyn Simulator, theta: &str, args: &SimulateArgs) -> Result<()> {
    let spec = sim.spec();
    let theta = parse_list(theta, "--theta").map_err(usage)?;
    spec.prior()
        .check(&theta, spec.param_names(), args.allow_outside_prior)
        .map_err(|e| {
            usage(format!(
                "--theta for {}: {e}{}",
                spec.name(),
                if matches!(e, twostage::models::SimError::OutsidePrior { .. }) {
                    " (--allow-outside-prior)"
                } else {
                    ""
                }
            ))
        })?;
    let mut record = spec.new_record();
    sim.simulate(
        &theta,
        &mut experiment_rng(args.seed.unwrap_or(0), args.experiment),
        &mut record,
    )
    .with_context(|| format!("simulating {} at theta = {theta:?}", spec.name()))?;
    let mut text = String::with_capacity(record.n_samples() * 48);
    text.push_str(&signal_header(spec));
    text.push('\n');
    push_record_rows(&mut text, None, &record);
    match &args.out {
        Some(path) => twostage::write_whole(path, text.as_bytes())?,
        None => crate::standard_output::StandardOutput::write_text(&text)?,
    }
    Ok(())
}

/// `--at ESTIMATES.csv [--input RECORD.csv]`.
fn at_estimates(sim: &dyn Simulator, at: &Path, args: &SimulateArgs) -> Result<()> {
    let spec = sim.spec();
    let mut rows = predict::read_rows(at, spec.param_names())?;
    let from = at.display().to_string();
    let values = rows.iter().map(|r| (r.id.as_str(), &r.theta));
    if !args.allow_outside_prior
        && let Some(outside) = twostage::values_outside_prior(&from, values, spec)
    {
        return Err(usage(format!(
            "{}: {outside}",
            crate::estimate::OUTSIDE_PRIOR_FLAGS
        )));
    }
    let inputs = match &args.input {
        None => predict::Inputs::Own,
        Some(path) => predict::Inputs::read(path, &RecordFormat::of(spec), &rows)?,
    };
    let start = std::time::Instant::now();
    if let Some(samples) = args.own_from_first {
        fit_own(sim, &mut rows, &inputs, samples, args.seed.unwrap_or(0))?;
    }
    // Progress: a bar on a terminal, else a line every 10 s of a long run.
    let bars = crate::bars::Bars::new(false);
    bars.begin_step("simulating at estimates", rows.len(), "records");
    let records = predict::simulate_rows(
        sim,
        &rows,
        &inputs,
        args.noiseless,
        args.seed.unwrap_or(0),
        &bars,
    )?;
    bars.end_step();
    let level = match args.band {
        None => None,
        Some(p) if p > 0.0 && p < 100.0 => Some(p / 100.0),
        Some(p) => {
            return Err(usage(format!(
                "--band {p}: a band's level is a percentage between 0 and 100, such as 90"
            )));
        }
    };
    let bands = level.map(|l| predict::bands(&rows, &records, l));
    let text = match &bands {
        Some(bands) => predict::bands_csv(sim, bands, &records),
        None => predict::records_csv(sim, &rows, &records),
    };
    // Against a record's own outputs: the prediction error a user validates
    // an identified model by (with a band: its mean, and the share of the
    // record's samples inside it).
    let predictions: Vec<(&str, usize, Option<&predict::Band>)> = match &bands {
        Some(bands) => bands
            .iter()
            .map(|b| (b.id.as_str(), b.rows[0], Some(b)))
            .collect(),
        None => rows
            .iter()
            .enumerate()
            .map(|(i, r)| (r.id.as_str(), i, None))
            .collect(),
    };
    for (id, i, band) in predictions {
        if let Some(measured) = inputs.of(i) {
            let n = measured.n_samples();
            let window =
                twostage::refine::scoring_window(n, args.score_from.unwrap_or(0), args.score_to)
                    .map_err(|e| match e {
                        twostage::RefineError::InvalidSetting(refused) => usage(format!(
                            "--{} {}: {} (the record of experiment {id})",
                            refused.name.replace(' ', "-"),
                            refused.value,
                            refused.reason,
                        )),
                        other => usage(other.to_string()),
                    })?;
            let (from, to) = (window.start, window.end);
            let parts: Vec<String> = spec
                .output_names()
                .iter()
                .enumerate()
                .map(|(j, name)| {
                    let measured = &measured.output(j)[from..to];
                    let Some(band) = band else {
                        let (rms, fit) =
                            twostage::output_fit(measured, &records[i].output(j)[from..to]);
                        return format!("{name} RMS {}, fit {fit:.1}%", four_digits(rms));
                    };
                    let predicted = &band.outputs[j][from..to];
                    let mean: Vec<f64> = predicted.iter().map(|p| p[0]).collect();
                    let (rms, fit) = twostage::output_fit(measured, &mean);
                    let inside = measured
                        .iter()
                        .zip(predicted)
                        .filter(|(y, p)| (p[1]..=p[2]).contains(*y))
                        .count();
                    format!(
                        "{name} RMS {} of the band's mean, fit {fit:.1}%, {:.1}% of samples \
                         inside the band",
                        four_digits(rms),
                        100.0 * inside as f64 / measured.len().max(1) as f64
                    )
                })
                .collect();
            eprintln!(
                "experiment {id}: against the given record's outputs{}: {}",
                match (from, to) {
                    (0, to) if to == n => String::new(),
                    (from, to) if to == n => format!(" from sample {from}"),
                    (from, to) => format!(" from sample {from} to {}", to - 1),
                },
                parts.join("; ")
            );
        }
    }
    match &args.out {
        Some(path) => twostage::write_whole(path, text.as_bytes())?,
        None => crate::standard_output::StandardOutput::write_text(&text)?,
    }
    eprintln!(
        "simulated {} at {} estimate(s) of {}{}{} in {:.1} s",
        spec.name(),
        rows.len(),
        at.display(),
        if args.input.is_some() {
            ", on the given input"
        } else {
            ""
        },
        if args.noiseless {
            ", without noise"
        } else {
            ""
        },
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `--own-from-first K`: each row's own parameters fitted to the first
/// `samples` samples of its record, said on stderr.
fn fit_own(
    sim: &dyn Simulator,
    rows: &mut [predict::Row],
    inputs: &predict::Inputs,
    samples: usize,
    seed: u64,
) -> Result<()> {
    let spec = sim.spec();
    let own: Vec<usize> = (0..spec.n_params())
        .filter(|&j| spec.per_record()[j])
        .collect();
    let search = twostage::refine::SearchStarts {
        from_prior: twostage::refine::SearchStarts::default_from_prior(own.len()),
        seed,
    };
    for (i, row) in rows.iter_mut().enumerate() {
        let Some(record) = inputs.of(i) else { continue };
        let found = twostage::fit_own_parameters(sim, record, &row.theta, samples, search)
            .map_err(|e| match e {
                twostage::RefineError::InvalidSetting(refused) => usage(format!(
                    "--own-from-first {samples}: {} (the record of experiment {})",
                    refused.reason, row.id
                )),
                other => anyhow::anyhow!(
                    "--own-from-first {samples}: the record of experiment {}: {other}",
                    row.id
                ),
            })?;
        let values: Vec<String> = own
            .iter()
            .map(|&j| {
                format!(
                    "{} = {}",
                    spec.param_names()[j],
                    four_digits(found.theta[j])
                )
            })
            .collect();
        eprintln!(
            "experiment {}: its own parameters fitted to its first {samples} samples: {} ({})",
            row.id,
            values.join(", "),
            found.stop.name()
        );
        row.theta = found.theta;
    }
    Ok(())
}

/// One shard of a training run's charts.
fn one_shard(
    model: &crate::model_arg::Model,
    sim: &dyn Simulator,
    shard: &str,
    count: usize,
    args: &SimulateArgs,
) -> Result<()> {
    let dir = args
        .out
        .as_ref()
        .ok_or_else(|| usage("--shard needs --out DIR, the folder of the shard files".into()))?;
    if args.noiseless {
        return Err(usage(
            "--noiseless changes the model: shards must be the training run's own records".into(),
        ));
    }
    let index = twostage::ShardIndex::resolve(shard, |name| std::env::var(name).ok()).or_usage()?;
    // The shards hold the charts of the run `train` makes of this request.
    let request = twostage::TrainingRequest {
        simulations: Some(count),
        compress: args.compress.clone(),
        settings: RunSettings {
            seed: args.seed,
            validation: args.validate,
            calibration: args.calibrate,
            ..RunSettings::default()
        },
        ..twostage::TrainingRequest::default()
    };
    let plan = request.shard_plan(model.named()).or_usage()?;
    let start = std::time::Instant::now();
    let path = twostage::simulate_shard(sim, &plan, index, dir).map_err(|e| {
        if e.is_setting() {
            usage(e.to_string())
        } else {
            anyhow::Error::new(e).context(format!("simulating shard {shard}"))
        }
    })?;
    eprintln!(
        "wrote shard {} of {} ({} training, {} calibration, {} validation records) to {} in {:.1} s",
        index.index,
        index.count,
        index.range(count).len(),
        index.range(args.calibrate).len(),
        index.range(args.validate).len(),
        path.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Characters a number takes in the files at most, as `format_f64`
/// writes it (a sign, 17 significant digits, a point and an exponent), and
/// the comma after it.
const NUMBER_WIDTH: u64 = 25;

/// What `count` records of `spec`'s model take in `dir`, said up front,
/// and refused where the disk has less room, with the `--count` that fits.
fn room_for(spec: &twostage::models::ModelSpec, count: usize, dir: &Path) -> Result<()> {
    let index = count.to_string().len() as u64 + 1;
    let signals = (spec.input_names().len() + spec.output_names().len()) as u64;
    let record = spec.n_samples() as u64 * (index + signals * NUMBER_WIDTH)
        + index
        + spec.n_params() as u64 * NUMBER_WIDTH;
    // In f64: a hostile count overflows u64 bytes.
    let total = record as f64 * count as f64;
    if let Some(free) = twostage::models::free_disk(dir)
        && total > free as f64
    {
        return Err(anyhow::anyhow!(
            "--count {count} would write up to {} to {} ({} a record of {} samples), \
             where its disk has {} free: at most --count {} fits, or write elsewhere",
            readable_bytes(total),
            dir.display(),
            readable_bytes(record as f64),
            spec.n_samples(),
            readable_bytes(free as f64),
            free / record.max(1)
        ));
    }
    eprintln!(
        "writing {count} records to {}: up to {} ({} a record)",
        dir.display(),
        readable_bytes(total),
        readable_bytes(record as f64)
    );
    Ok(())
}

fn many_experiments(sim: &dyn Simulator, count: usize, seed: u64, dir: &Path) -> Result<()> {
    if count == 0 {
        return Err(usage("--count must be at least 1".into()));
    }
    let spec = sim.spec();
    room_for(spec, count, dir)?;
    let chart = write_csv_chart(sim, count, seed, dir)?;
    eprintln!(
        "wrote {count} experiments of {} to {} and {}",
        spec.name(),
        chart.data.display(),
        chart.truth.display()
    );
    Ok(())
}

/// The model's signal names (`estimate` reads them, and the generic
/// `u,y` names, back).
fn signal_header(spec: &twostage::models::ModelSpec) -> String {
    row(spec.input_names().iter().chain(spec.output_names()))
        .trim_end()
        .to_string()
}
