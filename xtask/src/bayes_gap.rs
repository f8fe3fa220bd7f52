//! How far an estimator of a built-in model sits from the Bayes limit: its
//! RMSE and the exact posterior mean's on the same fresh records, per
//! parameter (the limit moves from test set to test set, so only a shared
//! set gives a ratio worth quoting), with a bootstrap interval of each
//! ratio over the records. The car may be driven by another steering than
//! its chicane (a standard manoeuvre every record shares, on which the
//! posterior's grid is simulated), and a second estimator may be set
//! beside the first on the same records.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use twostage::models::{
    BuiltinModel, BuiltinOverrides, Drawn, InputSignal, IoData, Simulator, StreamPurpose,
    experiment_rng, stream_rng,
};
use twostage::sources::{ChartFiles, csv_rows::read_columns};
use twostage::{Assessment, ClassicMethod, EstimateWorkspace, Estimator, interval_in_box};
use twostage_baselines::{
    BayesBenchmark, BayesCar, InitialCovariance, MethodSettings, RecordEstimator, classic_estimator,
};

use twostage::validate::{COVERAGE_LEVELS, PosteriorCalibration};

use crate::c2st::Reference;
use crate::paper::test_records;
use crate::posterior_cache;

/// The posterior means of `records` (of parameters `truth`, `dim` each) by
/// `bayes`, read from where an earlier run kept them (that place is
/// returned) or computed and kept under `target/bayes-gap`.
pub(crate) fn posterior_means(
    bayes: &dyn RecordEstimator,
    truth: &[Vec<f64>],
    records: &[IoData],
    dim: usize,
) -> Result<(Vec<Vec<f64>>, Option<PathBuf>)> {
    let kept = posterior_cache::path(
        &crate::target_dir().join("bayes-gap"),
        posterior_cache::key(truth, records),
    );
    if let Some(posterior) = posterior_cache::load(&kept, records.len(), dim) {
        return Ok((posterior, Some(kept)));
    }
    let posterior: Vec<Vec<f64>> = records
        .par_iter()
        .map(|record| bayes.estimate(record).map(|e| e.theta))
        .collect::<Result<_, _>>()?;
    posterior_cache::store(&kept, &posterior)
        .with_context(|| format!("keeping the posterior means in {}", kept.display()))?;
    Ok((posterior, None))
}

/// The car's test records of one manoeuvre and their exact posterior means.
pub(crate) struct CarManoeuvre {
    /// The car driven by the manoeuvre.
    pub car: Box<dyn Simulator>,
    /// Each record's parameters.
    pub truth: Vec<Vec<f64>>,
    /// The records.
    pub records: Vec<IoData>,
    /// Each record's exact posterior mean.
    pub posterior: Vec<Vec<f64>>,
}

/// `count` fresh records of the car driven by `steering` (seed 2026, as
/// `bayes-gap` draws them) and their exact posterior means.
pub(crate) fn car_manoeuvre(steering: Steering, count: usize) -> Result<CarManoeuvre> {
    let given = manoeuvre(steering)?;
    let overrides = BuiltinOverrides {
        input: given.clone().map(InputSignal::fixed).transpose()?,
        ..BuiltinOverrides::default()
    };
    let car = BuiltinModel::Pacejka.build_with(&overrides)?;
    let (truth, records) = test_records(car.as_ref(), count, 2026)?;
    let bayes: Box<dyn RecordEstimator> = match given {
        Some(steer) => Box::new(BayesCar::on_steering(129, 65, steer)?),
        None => Box::new(BayesCar::new(
            129,
            65,
            records.first().map_or(0, IoData::n_samples),
        )?),
    };
    let (posterior, _) = posterior_means(bayes.as_ref(), &truth, &records, car.prior().dim())?;
    Ok(CarManoeuvre {
        car,
        truth,
        records,
        posterior,
    })
}

/// What drives the car in the test records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Steering {
    /// The paper's chicane (the car's own input).
    Chicane,
    /// An ISO 3888-1 double lane change, open loop.
    Iso3888,
    /// A sine with dwell (FMVSS 126).
    SineWithDwell,
    /// A step steer (ISO 7401): a fast ramp to a held steer.
    StepSteer,
    /// A slalom: four cycles of one sine, steered on without rest.
    Slalom,
    /// A slow ramp to a steer held near the tires' saturation.
    RampHold,
    /// Band-limited random steering, one draw every record shares.
    Random,
}

/// The car's sample time and record length (docs/../spec/pacejka-car.md).
const CAR_SAMPLE_TIME: f64 = 0.02;
const CAR_SAMPLES: usize = 500;

/// One period of a sine of `amplitude` over `duration` s from `start`.
fn sine_period(t: f64, start: f64, duration: f64, amplitude: f64) -> f64 {
    if (start..start + duration).contains(&t) {
        amplitude * (std::f64::consts::TAU * (t - start) / duration).sin()
    } else {
        0.0
    }
}

/// The road-wheel steering of a manoeuvre at the car's 10 m/s, sampled
/// as the car's records are. ISO 3888-1 (2018) sets a 3.5 m lane offset
/// reached over 30 m and left over 25 m, between 15 m and 25 m of
/// straight track: at 10 m/s one sine period of steering over 3 s, 2.5 s
/// straight, one period back over 2.5 s, its amplitude making the lateral
/// displacement of a sinusoidal acceleration (a T^2 / (2 pi)) 3.5 m at the
/// car's linear gain of about 35 m/s^2 per rad (0.07 and 0.10 rad). The
/// sine with dwell of FMVSS 126 steers a 0.7 Hz sine, holds its second
/// peak 0.5 s, and returns; at the chicane's 0.2 rad amplitude, from 1 s.
/// The step steer of ISO 7401 ramps in 0.15 s (a steering-wheel rate
/// within its 200 to 500 deg/s at a 15:1 ratio) to 0.1 rad, about
/// 3.5 m/s^2, and holds it; the slalom steers 0.1 rad at 0.5 Hz for 8 s;
/// the ramp reaches 0.25 rad (near the tires' limit of about mu g over the
/// linear gain) in 4 s and holds it; the random steering is band-limited
/// noise below 1 Hz of RMS 0.05 rad, drawn once.
pub(crate) fn manoeuvre(steering: Steering) -> Result<Option<Vec<f64>>> {
    let at = |k: usize| k as f64 * CAR_SAMPLE_TIME;
    let values: Vec<f64> = match steering {
        Steering::Chicane => return Ok(None),
        Steering::Iso3888 => (0..CAR_SAMPLES)
            .map(|k| sine_period(at(k), 1.5, 3.0, 0.07) - sine_period(at(k), 7.0, 2.5, 0.10))
            .collect(),
        Steering::SineWithDwell => {
            let (start, frequency, dwell, amplitude) = (1.0, 0.7, 0.5, 0.2);
            let period = 1.0 / frequency;
            let sine = |t: f64| amplitude * (std::f64::consts::TAU * frequency * t).sin();
            (0..CAR_SAMPLES)
                .map(|k| {
                    let t = at(k) - start;
                    if t < 0.0 {
                        0.0
                    } else if t < 0.75 * period {
                        sine(t)
                    } else if t < 0.75 * period + dwell {
                        -amplitude
                    } else if t < period + dwell {
                        sine(t - dwell)
                    } else {
                        0.0
                    }
                })
                .collect()
        }
        Steering::StepSteer => (0..CAR_SAMPLES)
            .map(|k| 0.1 * ((at(k) - 1.0) / 0.15).clamp(0.0, 1.0))
            .collect(),
        Steering::Slalom => (0..CAR_SAMPLES)
            .map(|k| {
                let t = at(k) - 1.0;
                if (0.0..8.0).contains(&t) {
                    0.1 * (std::f64::consts::TAU * 0.5 * t).sin()
                } else {
                    0.0
                }
            })
            .collect(),
        Steering::RampHold => (0..CAR_SAMPLES)
            .map(|k| 0.25 * ((at(k) - 1.0) / 4.0).clamp(0.0, 1.0))
            .collect(),
        Steering::Random => {
            let noise =
                InputSignal::filtered_noise(0.0, Drawn::fixed(1.0), 4, Drawn::fixed(0.05), 0.0)?;
            let mut values = vec![0.0; CAR_SAMPLES];
            noise.fill(
                CAR_SAMPLE_TIME,
                &mut experiment_rng(RANDOM_STEERING_SEED, 0),
                &mut values,
            )?;
            values
        }
    };
    Ok(Some(values))
}

/// The seed of the random steering's one draw.
const RANDOM_STEERING_SEED: u64 = 7401;

/// Root mean squared error of parameter j over the records `rows` (an
/// index may repeat: a bootstrap resample).
pub(crate) fn rmse(estimates: &[Vec<f64>], truth: &[Vec<f64>], j: usize, rows: &[usize]) -> f64 {
    let sse: f64 = rows
        .iter()
        .map(|&i| (estimates[i][j] - truth[i][j]).powi(2))
        .sum();
    (sse / rows.len().max(1) as f64).sqrt()
}

/// The 2.5% and 97.5% quantiles of the ratio of two estimators' RMSE of
/// parameter j over 2000 resamples of the records (the same resample for
/// both: the ratio's own uncertainty, not the two RMSEs' separately).
pub(crate) fn bootstrap_ratio(
    ours: &[Vec<f64>],
    theirs: &[Vec<f64>],
    truth: &[Vec<f64>],
    j: usize,
    seed: u64,
) -> [f64; 2] {
    let n = truth.len();
    let mut ratios: Vec<f64> = (0..2000u64)
        .into_par_iter()
        .map(|b| {
            // SplitMix64 per resample: a deterministic stream of indices.
            let mut state = seed ^ b.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let rows: Vec<usize> = (0..n)
                .map(|_| {
                    state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
                    let mut z = state;
                    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                    ((z ^ (z >> 31)) % n as u64) as usize
                })
                .collect();
            rmse(ours, truth, j, &rows) / rmse(theirs, truth, j, &rows)
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    [ratios[50], ratios[1949]]
}

fn estimates(estimator: &Estimator, records: &[twostage::models::IoData]) -> Result<Vec<Vec<f64>>> {
    Ok(assessments(estimator, records)?
        .into_iter()
        .map(|a| a.theta)
        .collect())
}

fn assessments(estimator: &Estimator, records: &[IoData]) -> Result<Vec<Assessment>> {
    Ok(records
        .par_iter()
        .map_init(EstimateWorkspace::new, |work, record| {
            estimator.assess_with(record.inputs(), record.outputs(), work)
        })
        .collect::<Result<_, _>>()?)
}

/// What the estimator says of its own estimates on the test records: the
/// share of records each parameter's interval covers the truth of, and
/// the share it flags out of distribution (by the features, by the input).
fn said_of_itself(estimator: &Estimator, assessed: &[Assessment], truth: &[Vec<f64>]) -> String {
    let n = assessed.len().max(1) as f64;
    let share = |count: usize| count as f64 / n;
    let mut words = Vec::new();
    if let Some(level) = estimator.intervals().map(|c| 1.0 - c.alpha()) {
        let covered: Vec<String> = estimator
            .param_names()
            .iter()
            .enumerate()
            .map(|(j, name)| {
                let inside = assessed
                    .iter()
                    .zip(truth)
                    .filter(|(a, t)| {
                        a.interval_half_widths().is_some_and(|w| {
                            let (low, high) =
                                interval_in_box(&a.theta, w, estimator.lower(), estimator.upper());
                            (low[j]..=high[j]).contains(&t[j])
                        })
                    })
                    .count();
                format!("{name} {:.3}", share(inside))
            })
            .collect();
        words.push(format!(
            "{:.0}% intervals cover {}",
            100.0 * level,
            covered.join(", ")
        ));
    }
    let flagged = assessed.iter().filter(|a| a.out_of_distribution()).count();
    let by_features = assessed.iter().filter(|a| a.features_outside()).count();
    let by_input = assessed
        .iter()
        .filter(|a| !a.input_deviations.is_empty())
        .count();
    let by_shape = assessed.iter().filter(|a| a.input_shape_outside()).count();
    words.push(format!(
        "flagged out of distribution {:.3} (features {:.3}, input's summary {:.3}, input's \
         shape {:.3})",
        share(flagged),
        share(by_features),
        share(by_input),
        share(by_shape)
    ));
    words.join("; ")
}

/// Draws of each record from an estimator's posterior: their means, and
/// their calibration against the truth.
struct PosteriorScores {
    means: Vec<Vec<f64>>,
    calibration: PosteriorCalibration,
}

/// Draws per record.
const DRAWS: usize = 1000;

/// A record's truth among its draws: per parameter its rank, and the
/// region level that holds it ([`Estimator::truth_ranks`]).
type Ranked = (Vec<f64>, f64);

impl PosteriorScores {
    fn coverage_words(&self, j: usize) -> String {
        let c = &self.calibration;
        format!(
            "{}; ranks' distance from uniform {:.3} (p {:.3})",
            levels_words(&c.central[j]),
            c.uniformity_distance[j],
            c.uniformity_p[j]
        )
    }
}

/// Shares at each of [`COVERAGE_LEVELS`], in words.
fn levels_words(shares: &[f64; 3]) -> String {
    COVERAGE_LEVELS
        .iter()
        .zip(shares)
        .map(|(level, share)| format!("{:.0}%: {share:.3}", 100.0 * level))
        .collect::<Vec<_>>()
        .join(", ")
}

/// [`DRAWS`] draws of every record from `estimator`'s posterior (record i
/// from the stream of (`seed`, i), as `estimate --samples` draws), timed.
fn posterior_draws(
    estimator: &Estimator,
    records: &[IoData],
    truth: &[Vec<f64>],
    seed: u64,
) -> Result<PosteriorScores> {
    let q = estimator.param_names().len();
    let start = Instant::now();
    let per_record: Vec<(Vec<f64>, Ranked)> = records
        .par_iter()
        .enumerate()
        .map_init(EstimateWorkspace::new, |work, (i, record)| {
            let mut draws = vec![0.0; DRAWS * q];
            let mut rng = stream_rng(seed, i as u64, StreamPurpose::Posterior);
            let ranked = estimator.truth_ranks(
                (record.inputs(), record.outputs()),
                work,
                &mut rng,
                &mut draws,
                &truth[i],
            )?;
            let mean = (0..q)
                .map(|j| draws.iter().skip(j).step_by(q).sum::<f64>() / DRAWS as f64)
                .collect();
            Ok::<_, anyhow::Error>((mean, ranked))
        })
        .collect::<Result<_>>()?;
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "  posterior: {DRAWS} draws of each record and their densities in {seconds:.2} s \
         ({:.0} draws a second, features and densities included)",
        (DRAWS * records.len()) as f64 / seconds
    );
    let (means, ranked): (Vec<Vec<f64>>, Vec<Ranked>) = per_record.into_iter().unzip();
    let (ranks, levels): (Vec<Vec<f64>>, Vec<f64>) = ranked.into_iter().unzip();
    Ok(PosteriorScores {
        means,
        calibration: PosteriorCalibration::from_ranks(&ranks, &levels, DRAWS)?,
    })
}

/// Which records an estimator is tested on.
pub(crate) struct TestRecords {
    /// The built-in model (default: the estimator's).
    pub(crate) model: Option<BuiltinModel>,
    /// What steers the car.
    pub(crate) steering: Steering,
    /// How many fresh records.
    pub(crate) count: usize,
    /// Their seed.
    pub(crate) seed: u64,
    /// A chart folder whose records are tested instead of fresh ones.
    pub(crate) chart: Option<PathBuf>,
}

/// The records of a chart folder and their truth, each checked to be
/// steered by `given` where a manoeuvre is given (the Bayes posterior of
/// the car is computed on that steering; the model's own input is taken
/// as the records have it).
fn chart_records(
    dir: &Path,
    simulator: &dyn Simulator,
    given: Option<&[f64]>,
) -> Result<(Vec<Vec<f64>>, Vec<IoData>)> {
    let spec = simulator.spec();
    let chart = ChartFiles::open(dir, spec)?;
    let (mut truth, mut records) = (Vec::new(), Vec::new());
    chart.for_each_record(spec, |row, record| {
        truth.push(chart.theta(row).to_vec());
        records.push(record.clone());
        Ok(())
    })?;
    let differs = |r: &IoData, expected: &[f64]| {
        r.input(0)
            .iter()
            .zip(expected)
            .any(|(a, b)| (a - b).abs() > 1e-9 * (1.0 + b.abs()))
    };
    if let Some(k) = given.and_then(|expected| records.iter().position(|r| differs(r, expected))) {
        bail!(
            "{}: record {k}'s input is not the steering the Bayes posterior is computed on \
             (--steering)",
            dir.display()
        );
    }
    Ok((truth, records))
}

/// Estimates of a chart's records from `twostage estimate`'s CSV, in the
/// chart's order (its experiment ids the truth's).
fn read_estimates(path: &Path, chart: &Path, names: &[String]) -> Result<Vec<Vec<f64>>> {
    let id = ["experiment".to_string()];
    let ids = read_columns(path, &id)?;
    let truth_ids = read_columns(&chart.join("truth.csv"), &id)?;
    if ids != truth_ids {
        bail!(
            "{}: its experiments are not {}'s, in its order",
            path.display(),
            chart.display()
        );
    }
    let columns = read_columns(path, names)?;
    Ok((0..ids[0].len())
        .map(|i| columns.iter().map(|c| c[i]).collect())
        .collect())
}

pub(crate) fn run(
    path: &Path,
    against: Option<&Path>,
    test: TestRecords,
    scored: &[PathBuf],
    (c2st, drawn_file): (usize, Option<&Path>),
) -> Result<()> {
    let TestRecords {
        model,
        steering,
        count,
        seed,
        chart,
    } = test;
    let load = |path: &Path| {
        Estimator::load(path).with_context(|| format!("reading the estimator {}", path.display()))
    };
    let estimator = load(path)?;
    let kind = match model {
        Some(kind) => kind,
        None => match estimator.training().model.parse::<BuiltinModel>() {
            Ok(kind) => kind,
            Err(_) => bail!(
                "{} was trained on {}; name the built-in model its records are of with --model \
                 (benchmark, pacejka)",
                path.display(),
                estimator.training().model
            ),
        },
    };
    let given = manoeuvre(steering)?;
    if given.is_some() && kind != BuiltinModel::Pacejka {
        bail!("--steering drives the car (--model pacejka), not the {kind}");
    }
    let overrides = BuiltinOverrides {
        input: given.clone().map(InputSignal::fixed).transpose()?,
        ..BuiltinOverrides::default()
    };
    let simulator = kind.build_with(&overrides)?;
    let (truth, records) = match &chart {
        Some(dir) => chart_records(dir, simulator.as_ref(), given.as_deref())?,
        None => test_records(simulator.as_ref(), count, seed)?,
    };
    let count = records.len();
    let reference = match (kind, &given) {
        _ if c2st == 0 => None,
        (BuiltinModel::Benchmark, _) => Some(Reference::Benchmark(BayesBenchmark::default())),
        (BuiltinModel::Pacejka, Some(steering)) => Some(Reference::Car(Box::new(
            BayesCar::on_steering(129, 65, steering.clone())?,
        ))),
        (BuiltinModel::Pacejka, None) => Some(Reference::Car(Box::new(BayesCar::paper()?))),
    };
    let bayes: Box<dyn RecordEstimator> = match given {
        Some(steering) => Box::new(BayesCar::on_steering(129, 65, steering)?),
        None => {
            let settings = MethodSettings {
                initial_covariance: InitialCovariance::Eq6,
                particles: None,
                starts: 1,
                seed,
            };
            classic_estimator(kind, ClassicMethod::Bayes, &settings)?
        }
    };
    let start = Instant::now();
    let assessed = assessments(&estimator, &records)?;
    let ts_seconds = start.elapsed().as_secs_f64();
    let ts: Vec<Vec<f64>> = assessed.iter().map(|a| a.theta.clone()).collect();
    let mut others: Vec<(String, Vec<Vec<f64>>)> = Vec::new();
    if let Some(path) = against {
        others.push((
            path.display().to_string(),
            load(path).and_then(|e| estimates(&e, &records))?,
        ));
    }
    if let Some(dir) = &chart {
        for path in scored {
            others.push((
                path.display().to_string(),
                read_estimates(path, dir, estimator.param_names())?,
            ));
        }
    }
    let start = Instant::now();
    let (posterior, kept) =
        posterior_means(bayes.as_ref(), &truth, &records, simulator.prior().dim())?;
    let bayes_words = match kept {
        Some(kept) => format!("as kept in {}", kept.display()),
        None => format!("in {:.1} s", start.elapsed().as_secs_f64()),
    };
    let source = match &chart {
        Some(dir) => format!("the records of {}", dir.display()),
        None => format!("fresh records, seed {seed}"),
    };
    println!(
        "{count} {} records ({steering:?} steering, {source}): {} in {ts_seconds:.2} s, \
         the Bayes posterior mean {bayes_words}",
        simulator.spec().name(),
        path.display()
    );
    println!("  {}", said_of_itself(&estimator, &assessed, &truth));
    let drawn = match estimator.posterior() {
        Some(_) => Some(posterior_draws(&estimator, &records, &truth, seed)?),
        None => None,
    };
    let all: Vec<usize> = (0..records.len()).collect();
    for (j, name) in estimator.param_names().iter().enumerate() {
        let (ts_rmse, bayes_rmse) = (
            rmse(&ts, &truth, j, &all),
            rmse(&posterior, &truth, j, &all),
        );
        let [low, high] = bootstrap_ratio(&ts, &posterior, &truth, j, seed);
        println!(
            "  {name}: RMSE {ts_rmse:.5}, Bayes posterior mean RMSE {bayes_rmse:.5}; ratio {:.3} \
             [{low:.3}, {high:.3}]",
            ts_rmse / bayes_rmse
        );
        if let Some(drawn) = &drawn {
            let [low, high] = bootstrap_ratio(&drawn.means, &posterior, &truth, j, seed);
            println!(
                "  {name}: the posterior draws' mean RMSE {:.5}, over Bayes {:.3} [{low:.3}, \
                 {high:.3}]; central intervals of the draws cover {}",
                rmse(&drawn.means, &truth, j, &all),
                rmse(&drawn.means, &truth, j, &all) / bayes_rmse,
                drawn.coverage_words(j)
            );
        }
        for (label, other) in &others {
            let other_rmse = rmse(other, &truth, j, &all);
            let [low, high] = bootstrap_ratio(&ts, other, &truth, j, seed);
            let [bayes_low, bayes_high] = bootstrap_ratio(other, &posterior, &truth, j, seed);
            println!(
                "  {name}: {label} RMSE {other_rmse:.5}; the estimator's over it {:.3} \
                 [{low:.3}, {high:.3}]; it over Bayes {:.3} [{bayes_low:.3}, {bayes_high:.3}]",
                ts_rmse / other_rmse,
                other_rmse / bayes_rmse
            );
        }
    }
    if let Some(drawn) = &drawn {
        println!(
            "  the posterior's regions of highest density hold the whole parameter vector: {}",
            levels_words(&drawn.calibration.joint)
        );
    }
    if let Some(reference) = &reference {
        crate::c2st::run(&estimator, reference, &records, (c2st, drawn_file), seed)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sine_with_dwell_rises_falls_dwells_and_returns() {
        let u = manoeuvre(Steering::SineWithDwell).unwrap().unwrap();
        let at = |t: f64| u[(t / CAR_SAMPLE_TIME).round() as usize];
        assert_eq!(u.len(), CAR_SAMPLES);
        // Still before 1 s and after the manoeuvre's 1 / 0.7 + 0.5 s.
        assert!(u[..50].iter().all(|v| *v == 0.0));
        assert!(u[147..].iter().all(|v| *v == 0.0));
        // The first peak a quarter period in, then the dwell at the
        // second, 0.5 s (25 samples) long.
        assert!((at(1.0 + 0.25 / 0.7) - 0.2).abs() < 2e-3);
        let dwelling = u
            .iter()
            .filter(|v| v.to_bits() == (-0.2f64).to_bits())
            .count();
        assert!((25..=26).contains(&dwelling), "{dwelling}");
        // Continuous: no step larger than a sine's over one sample.
        let slope = 0.2 * std::f64::consts::TAU * 0.7 * CAR_SAMPLE_TIME;
        assert!(u.windows(2).all(|w| (w[1] - w[0]).abs() <= slope * 1.001));
    }

    #[test]
    fn the_double_lane_change_steers_out_and_back() {
        let u = manoeuvre(Steering::Iso3888).unwrap().unwrap();
        let largest = u.iter().fold(0.0f64, |m, v| m.max(*v));
        let smallest = u.iter().fold(0.0f64, |m, v| m.min(*v));
        assert!((largest - 0.10).abs() < 1e-3 && (smallest + 0.10).abs() < 1e-3);
        // Each lane change is a whole sine period: its steering sums to
        // zero, so the car leaves it heading straight.
        let first: f64 = u[75..225].iter().sum();
        let second: f64 = u[350..475].iter().sum();
        assert!(
            first.abs() < 1e-9 && second.abs() < 1e-9,
            "{first} {second}"
        );
        // The first change steers left first (positive), 0.07 at most.
        assert!(u[75..225].iter().all(|v| v.abs() <= 0.07 + 1e-12));
        assert!(u[80] > 0.0 && u[355] < 0.0);
    }

    /// A chart's records are tested only on the steering the posterior is
    /// computed on, and estimates only of the chart's own experiments.
    #[test]
    fn a_chart_of_another_steering_or_estimates_of_other_records_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let dwell = manoeuvre(Steering::SineWithDwell).unwrap().unwrap();
        let mut data = String::from("experiment,delta,a_y\n");
        for (id, steering) in [(0, &dwell[..]), (1, &[0.0; CAR_SAMPLES][..])] {
            for delta in steering {
                data.push_str(&format!("{id},{delta},0.1\n"));
            }
        }
        std::fs::write(dir.path().join("data.csv"), data).unwrap();
        let truth = "experiment,pK1,pK2\n0,-35,-1.1\n1,-30,-1.0\n";
        std::fs::write(dir.path().join("truth.csv"), truth).unwrap();
        let overrides = BuiltinOverrides {
            input: Some(InputSignal::fixed(dwell.clone()).unwrap()),
            ..BuiltinOverrides::default()
        };
        let car = BuiltinModel::Pacejka.build_with(&overrides).unwrap();
        let refused = chart_records(dir.path(), car.as_ref(), Some(&dwell)).unwrap_err();
        assert!(
            refused.to_string().contains("record 1's input"),
            "{refused}"
        );
        // Its first record alone is steered so: read with its truth.
        std::fs::write(
            dir.path().join("truth.csv"),
            "experiment,pK1,pK2\n0,-35,-1.1\n",
        )
        .unwrap();
        let data = std::fs::read_to_string(dir.path().join("data.csv")).unwrap();
        let first: String = data
            .lines()
            .take(1 + CAR_SAMPLES)
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(dir.path().join("data.csv"), first).unwrap();
        let (truth, records) = chart_records(dir.path(), car.as_ref(), Some(&dwell)).unwrap();
        assert_eq!((truth, records.len()), (vec![vec![-35.0, -1.1]], 1));
        let names = ["pK1".to_string(), "pK2".to_string()];
        let estimates = dir.path().join("estimates.csv");
        std::fs::write(&estimates, "experiment,pK1,pK2\n0,-34.5,-1.05\n").unwrap();
        assert_eq!(
            read_estimates(&estimates, dir.path(), &names).unwrap(),
            vec![vec![-34.5, -1.05]]
        );
        std::fs::write(&estimates, "experiment,pK1,pK2\n7,-34.5,-1.05\n").unwrap();
        let other = read_estimates(&estimates, dir.path(), &names).unwrap_err();
        assert!(other.to_string().contains("not"), "{other}");
    }
}
