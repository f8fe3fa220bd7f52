//! An estimator validated on fresh simulations of its model: the run that
//! `twostage validate` and Python's `Estimator.validate` both make, sized
//! by a count, by Theorem 1's accuracy, or grown until the certificate is
//! as tight as asked.

use ndarray::ArrayView2;
use rayon::prelude::*;
use twostage_estimate::EstimatorModel;
use twostage_estimator::{EstimateWorkspace, Estimator};
use twostage_models::{IoData, Sampling, Simulator, StreamPurpose, run_experiment, stream_rng};
use twostage_sources::{NamedModel, Progress, refuse_beyond_memory};
use twostage_train::{Error, Result};
use twostage_validate::{
    CALIBRATION_DRAWS, PosteriorCalibration, ValidationReport, hoeffding_sample_size,
    squared_error_bound,
};

/// What a validation run simulates and how it stops. Each field is named
/// as the setting that an error about it names.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationPlan {
    /// Fresh simulations r (with `target_rmse`, the first round); `None`:
    /// from `gamma`, else [`ValidationPlan::DEFAULT_SIMS`].
    pub sims: Option<usize>,
    /// Accuracy gamma of Theorem 1: r is then the smallest size that
    /// guarantees it with confidence 1 - `delta`.
    pub gamma: Option<f64>,
    /// Confidence parameter delta of Theorem 1 and of the certificates.
    pub delta: f64,
    /// Seed of the fresh simulations.
    pub seed: u64,
    /// Simulate until every certified RMSE is at most this many times the
    /// observed one, each round sized by the records the last predicts
    /// ([`ValidationReport::next_round`]), at most `max_sims`. The certificate holds
    /// at every r at once, so stopping when it is met keeps its
    /// confidence.
    pub target_rmse: Option<f64>,
    /// The most fresh simulations `target_rmse` may run.
    pub max_sims: usize,
}

impl ValidationPlan {
    /// Fresh simulations when neither `sims` nor `gamma` is given.
    pub const DEFAULT_SIMS: usize = 1000;
    /// The default seed, apart from every training seed's streams.
    pub const DEFAULT_SEED: u64 = 0x5641_4c49;
}

impl Default for ValidationPlan {
    fn default() -> Self {
        Self {
            sims: None,
            gamma: None,
            delta: 1e-3,
            seed: Self::DEFAULT_SEED,
            target_rmse: None,
            max_sims: 1_000_000,
        }
    }
}

/// Whether a validation grown toward `target_rmse` met it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TargetRmse {
    /// Every certified RMSE is within `ratio` times the observed one.
    Met {
        /// The largest certified-to-observed ratio at the end.
        ratio: f64,
    },
    /// `max_sims` ran out first.
    NotMet {
        /// The largest certified-to-observed ratio at the end.
        ratio: f64,
    },
}

/// A validation run's report and its records' truths and estimates.
#[derive(Debug, Clone)]
pub struct Validated {
    /// The report on every record run.
    pub report: ValidationReport,
    /// The records' true parameters, row-major (`records` x q).
    pub truth: Vec<f64>,
    /// The records' estimates, row-major (`records` x q).
    pub estimates: Vec<f64>,
    /// How many records ran.
    pub records: usize,
    /// The records run by the end of each round, the last `records`: one
    /// round unless `target_rmse` grew the run.
    pub rounds: Vec<usize>,
    /// With `target_rmse`: whether it was met.
    pub target: Option<TargetRmse>,
    /// Where the estimator has a posterior: its calibration on the same
    /// records ([`CALIBRATION_DRAWS`] draws each).
    pub posterior: Option<PosteriorCalibration>,
}

impl Validated {
    /// The report as JSON, with the posterior's calibration under the key
    /// `posterior` where there is one: what the command line's `validate
    /// --format json` prints and Python's `validate` returns.
    ///
    /// # Errors
    /// None in practice: the report's numbers are plain.
    pub fn report_json(&self) -> serde_json::Result<serde_json::Value> {
        let mut json = serde_json::to_value(&self.report)?;
        if let (Some(posterior), Some(object)) = (&self.posterior, json.as_object_mut()) {
            object.insert("posterior".into(), serde_json::to_value(posterior)?);
        }
        Ok(json)
    }
}

/// Validates `estimator` on fresh simulations of the model it was trained
/// on: the model file `given` where it was trained on one, else its
/// built-in model, found as every request finds it
/// ([`NamedModel::trained_on`]); then as [`validate_estimator`]. The
/// command line's `validate` and Python's `Estimator.validate` both run it.
///
/// ```
/// use twostage::{NamedModel, TwoStage, ValidationPlan, Silent, validate_trained};
/// use twostage::models::Benchmark;
/// let estimator = TwoStage::builder(&Benchmark::new())
///     .preset(twostage::paper_benchmark())
///     .simulations(300).validation(0).calibration(0).train()?;
/// let plan = ValidationPlan { sims: Some(100), ..ValidationPlan::default() };
/// assert_eq!(validate_trained(&estimator, None, &plan, &Silent)?.records, 100);
/// // A model file of another model is refused, by name.
/// let other = NamedModel::builtin("pacejka")?;
/// let refused = validate_trained(&estimator, Some(&other), &plan, &Silent).unwrap_err();
/// assert!(refused.to_string().contains("trained on 'benchmark'"), "{refused}");
/// # Ok::<(), twostage::Error>(())
/// ```
///
/// # Errors
/// A model given of another model than the estimator's, one that cannot
/// be started, and those of [`validate_estimator`].
pub fn validate_trained(
    estimator: &Estimator,
    given: Option<&NamedModel>,
    plan: &ValidationPlan,
    progress: &dyn Progress,
) -> Result<Validated> {
    let model = EstimatorModel::find(estimator, given)?.simulator()?;
    validate_estimator(estimator, model.as_ref(), plan, progress)
}

/// Validates `estimator` on fresh simulations of `model` (the model it was
/// trained on, run with its noise) as `plan` says, the records in
/// parallel, reported to `progress` as the step "validating". The
/// parameters are drawn independently from the prior whatever design the
/// model trains with: Theorem 1 and the certificates assume it. Record i
/// depends on (seed, i) alone, so the same plan gives the same bits on any
/// thread count, and each round of `target_rmse` extends the one before.
///
/// ```
/// use twostage::{TwoStage, ValidationPlan, Silent, validate_estimator};
/// use twostage::models::Benchmark;
///
/// let model = Benchmark::new();
/// let estimator = TwoStage::builder(&model)
///     .preset(twostage::paper_benchmark())
///     .simulations(300)
///     .validation(0)
///     .calibration(0)
///     .train()?;
/// let plan = ValidationPlan { sims: Some(200), ..ValidationPlan::default() };
/// let run = validate_estimator(&estimator, &model, &plan, &Silent)?;
/// assert_eq!(run.records, 200);
/// // The report's RMSE is the root mean squared error of the rows.
/// let mse = run.truth.iter().zip(&run.estimates).map(|(t, e)| (t - e).powi(2)).sum::<f64>() / 200.0;
/// assert!((run.report.parameters[0].rmse - mse.sqrt()).abs() < 1e-12);
/// # Ok::<(), twostage::Error>(())
/// ```
///
/// # Errors
/// A setting out of range (by its field's name: `sims`, `gamma`, `delta`,
/// `target_rmse`, `max_sims`), records that would not fit in memory, or a
/// simulation or estimate that fails.
pub fn validate_estimator(
    estimator: &Estimator,
    model: &dyn Simulator,
    plan: &ValidationPlan,
    progress: &dyn Progress,
) -> Result<Validated> {
    let (mut r, most) = sizes(estimator, plan)?;
    let q = estimator.param_names().len();
    let name = if plan.target_rmse.is_some() {
        "max_sims"
    } else {
        "sims"
    };
    refuse_beyond_memory(
        name,
        most,
        8 * 3 * q as u64,
        "records' parameters and estimates",
    )?;
    let prior = model.prior().clone().with_sampling(Sampling::Uniform);
    let design = prior.design(most, plan.seed)?;
    let (mut truth, mut estimates) = (Vec::new(), Vec::new());
    let (mut ranks, mut levels) = (Vec::new(), Vec::new());
    let mut rounds = vec![r];
    progress.begin_step("validating", most, "records");
    let outcome = loop {
        let done = truth.len() / q;
        let rows_of_round: Vec<Scored> = (done..r)
            .into_par_iter()
            .map_init(
                || (IoData::default(), EstimateWorkspace::new()),
                |(record, work), i| -> Result<Scored> {
                    let mut theta = vec![0.0; q];
                    run_experiment(model, &design, i, &mut theta, record)?;
                    let mut estimate = vec![0.0; q];
                    estimator.estimate_into(
                        record.inputs(),
                        record.outputs(),
                        work,
                        &mut estimate,
                    )?;
                    let drawn = match estimator.posterior() {
                        Some(_) => Some(posterior_ranks(
                            estimator,
                            record,
                            work,
                            &theta,
                            (plan.seed, i),
                        )?),
                        None => None,
                    };
                    progress.advance_step(1);
                    Ok((theta, estimate, drawn))
                },
            )
            .collect::<Result<_>>()?;
        for (theta, estimate, drawn) in rows_of_round {
            truth.extend(theta);
            estimates.extend(estimate);
            if let Some((rank, level)) = drawn {
                ranks.push(rank);
                levels.push(level);
            }
        }
        let report = ValidationReport::new(
            estimator.param_names(),
            rows(&truth, r, q),
            rows(&estimates, r, q),
            estimator.lower(),
            estimator.upper(),
            plan.delta,
            estimator.intervals().cloned(),
        )?;
        let Some(k) = plan.target_rmse else {
            break (report, None);
        };
        let ratio = report.certified_ratio();
        if ratio <= k {
            break (report, Some(TargetRmse::Met { ratio }));
        }
        if r == most {
            break (report, Some(TargetRmse::NotMet { ratio }));
        }
        r = report.next_round(k, most);
        rounds.push(r);
    };
    progress.end_step();
    let (report, target) = outcome;
    let posterior = if levels.is_empty() {
        None
    } else {
        Some(PosteriorCalibration::from_ranks(
            &ranks,
            &levels,
            CALIBRATION_DRAWS,
        )?)
    };
    Ok(Validated {
        report,
        truth,
        estimates,
        records: r,
        rounds,
        target,
        posterior,
    })
}

/// A validation record's truth, estimate, and with a posterior the
/// truth's ranks among the draws and the region level that holds it.
type Scored = (Vec<f64>, Vec<f64>, Option<(Vec<f64>, f64)>);

/// Record `i`'s truth `theta` among [`CALIBRATION_DRAWS`] draws of its
/// posterior, from the stream of (`seed`, `i`)
/// ([`Estimator::truth_ranks`]).
fn posterior_ranks(
    estimator: &Estimator,
    record: &IoData,
    work: &mut EstimateWorkspace,
    theta: &[f64],
    (seed, i): (u64, usize),
) -> Result<(Vec<f64>, f64)> {
    let mut draws = vec![0.0; CALIBRATION_DRAWS * theta.len()];
    let mut rng = stream_rng(seed, i as u64, StreamPurpose::Posterior);
    Ok(estimator.truth_ranks(
        (record.inputs(), record.outputs()),
        work,
        &mut rng,
        &mut draws,
        theta,
    )?)
}

/// The first round's records and the most the plan may run.
fn sizes(estimator: &Estimator, plan: &ValidationPlan) -> Result<(usize, usize)> {
    if !(plan.delta > 0.0 && plan.delta < 1.0) {
        return Err(Error::setting(
            "delta",
            plan.delta.to_string(),
            "a confidence parameter lies between 0 and 1, such as 1e-3",
        ));
    }
    let sigma = squared_error_bound(estimator.lower(), estimator.upper());
    let r = match (plan.sims, plan.gamma) {
        (Some(_), Some(_)) => {
            return Err(Error::setting(
                "gamma",
                format!("{:?}", plan.gamma),
                "sims and gamma both size the run: give one",
            ));
        }
        (Some(r), None) => r,
        (None, Some(gamma)) => usize::try_from(hoeffding_sample_size(sigma, gamma, plan.delta)?)
            .map_err(|_| {
                Error::setting(
                    "gamma",
                    gamma.to_string(),
                    "too small: the sample size overflows",
                )
            })?,
        (None, None) => ValidationPlan::DEFAULT_SIMS,
    };
    if r == 0 {
        return Err(Error::setting("sims", "0", "give at least 1"));
    }
    match plan.target_rmse {
        Some(k) if !(k.is_finite() && k > 1.0) => Err(Error::setting(
            "target_rmse",
            k.to_string(),
            "a certified RMSE is never below the observed one; give a multiple above 1, \
             such as 1.5",
        )),
        Some(_) if plan.max_sims < r => Err(Error::setting(
            "max_sims",
            plan.max_sims.to_string(),
            format!("below the first round of {r} simulations"),
        )),
        Some(_) => Ok((r, plan.max_sims)),
        None => Ok((r, r)),
    }
}

/// The first `r` records' values as rows of `q`; `values` holds exactly
/// them, one round after another.
fn rows(values: &[f64], r: usize, q: usize) -> ArrayView2<'_, f64> {
    ArrayView2::from_shape((r, q), values)
        .unwrap_or_else(|_| unreachable!("{} values are {r} records of {q}", values.len()))
}
