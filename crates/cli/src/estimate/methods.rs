//! What a record is estimated with: an estimator file, a classic method,
//! the multi-start output-error fit, or given values (`--at`); and the
//! options each reads.

use anyhow::Result;
use twostage::models::Simulator;
use twostage::models::{BuiltinModel, IoData};
use twostage::{Estimator, ModelProfile, OutputError, SignalNames};

use super::refine::{joint_fitter, model_file, model_of, refinement};
use super::{EstimateArgs, Estimated, Method, OUTPUT_ERROR, PriorBox};
use crate::OrUsage;
use crate::options::InitialCovariance;
use crate::{csv_records, usage};

/// The model named by --model or --model-file, which `what` needs.
fn named_model(args: &EstimateArgs, what: &str) -> Result<twostage::NamedModel> {
    crate::model_arg::named(args.model.as_deref(), args.model_file.as_deref())?.ok_or_else(|| {
        usage(format!(
            "{what} simulates the model: give --model M or --model-file F"
        ))
    })
}

/// Refuses an option that the chosen way of estimating would not read:
/// an option silently ignored reads as one that worked.
fn refuse_what_does_not_apply(args: &EstimateArgs) -> Result<()> {
    let method = args.method.as_deref();
    let running = match (method, &args.estimator, &args.at) {
        (Some(m), _, _) => format!("--method {m}"),
        (None, Some(_), _) => "an estimator".to_string(),
        (None, None, Some(_)) => "--at".to_string(),
        (None, None, None) => return Ok(()),
    };
    let is = |names: &[&str]| method.is_some_and(|m| names.contains(&m));
    let refuse = |option: &str, readers: &str| {
        Err(usage(format!(
            "{option} is read by {readers}; {running} does not read it: leave it out"
        )))
    };
    if (args.check_sims.is_some() || args.plot.is_some() || args.score_from.is_some())
        && !args.checks()
    {
        return refuse(
            "--check-sims, --plot and --score-from",
            "--check and --refine=auto",
        );
    }
    if args.model_file.is_some()
        && args.estimator.is_some()
        && !(args.checks() || args.refine.is_some() || args.joint)
    {
        return refuse(
            "--model-file",
            "--check, --refine and --joint with an estimator (it knows its model's records)",
        );
    }
    if args.model.is_some() && method.is_none() && args.at.is_none() {
        return refuse(
            "--model",
            "--method and --at (an estimator knows its model)",
        );
    }
    if args.correlation && args.refine.is_none() && !args.joint {
        return refuse("--correlation", "--refine and --joint");
    }
    if args.p0.is_some() && !is(&["ekf", "ukf"]) {
        return refuse("--p0", "--method ekf and ukf");
    }
    if args.particles.is_some() && !is(&["pf"]) {
        return refuse("--particles", "--method pf");
    }
    if args.starts.is_some() && !is(&["pem", "ii", OUTPUT_ERROR]) {
        return refuse("--starts", "--method pem, ii and oe");
    }
    if args.seed.is_some()
        && !args.checks()
        && !args.joint
        && !is(&["pf", "pem", "ii", OUTPUT_ERROR])
    {
        return refuse("--seed", "--method pf, pem, ii and oe, --check and --joint");
    }
    Ok(())
}

/// The signals of a model's records, as its CSV files name them.
fn record_format(spec: &twostage::models::ModelSpec) -> csv_records::RecordFormat {
    csv_records::RecordFormat {
        signals: SignalNames {
            inputs: spec.input_names().to_vec(),
            outputs: spec.output_names().to_vec(),
        },
        sample_time: spec.sample_time(),
    }
}

/// An estimate that is nothing but its parameters.
pub(super) fn bare(theta: Vec<f64>) -> Estimated {
    Estimated {
        theta,
        widths: None,
        distance: None,
        input: None,
        floored: None,
        check: None,
        refined: None,
        interval_failure: None,
        correlation: None,
        optima: None,
        window_end: None,
    }
}

/// `--method oe`: a multi-start output-error fit of any model that can
/// run without noise on a given input.
fn output_error_method(args: &EstimateArgs) -> Result<Chosen> {
    let named = named_model(args, "--method oe")?;
    let simulator = named.simulator(false).or_usage()?;
    let format = record_format(simulator.spec());
    let names = simulator.spec().param_names().to_vec();
    let checker = check_model(args)?;
    let fit = OutputError::new(simulator).usage_context("--method oe")?;
    let oe = twostage_baselines::PredictionError::new(fit, args.starts.unwrap_or(DEFAULT_STARTS))
        .seed(args.seed.unwrap_or(0))
        .named(OUTPUT_ERROR);
    Ok(Chosen {
        names,
        format,
        trained: None,
        checker,
        refiner: None,
        prior_box: None,
        joint: None,
        method: Box::new(move |_, record: &IoData| {
            let best = oe
                .descents(record)
                .map_err(|e| e.to_string())?
                .into_iter()
                .next()
                .ok_or_else(|| "no start".to_string())?;
            Ok(Estimated {
                refined: Some(Ok(Some(best.stop))),
                ..bare(best.theta)
            })
        }),
    })
}

/// `--at VALUES.csv`: given values, one row for every record or a row per
/// experiment, to be checked.
fn given_values(args: &EstimateArgs, path: &std::path::Path) -> Result<Chosen> {
    let named = named_model(args, "--at")?;
    let simulator = named.simulator(false).or_usage()?;
    let spec = simulator.spec().clone();
    let rows = crate::predict::read_rows(path, spec.param_names())?;
    crate::predict::refuse_outside_prior(&rows, &spec, path, args.allow_outside_prior)?;
    let file = path.display().to_string();
    let one = (rows.len() == 1).then(|| rows[0].theta.clone());
    let mut by_id = std::collections::HashMap::new();
    if one.is_none() {
        for row in rows {
            let id = row.id.clone();
            if by_id.insert(row.id, row.theta).is_some() {
                return Err(usage(format!(
                    "{file}: experiment {id} has two rows of values: give one per experiment"
                )));
            }
        }
    }
    let values = move |id: &str| match &one {
        Some(theta) => Ok(theta.clone()),
        None => by_id.get(id).cloned().ok_or_else(|| {
            format!(
                "{file} has no row for experiment {id}: give a row per experiment, or a single \
                 row for every record"
            )
        }),
    };
    Ok(Chosen {
        names: spec.param_names().to_vec(),
        format: record_format(&spec),
        trained: None,
        checker: Some(simulator),
        refiner: None,
        prior_box: None,
        joint: None,
        method: Box::new(move |id, _| values(id).map(bare)),
    })
}

/// The model --check simulates for --method and --at: --model or
/// --model-file.
fn check_model(args: &EstimateArgs) -> Result<Option<Box<dyn Simulator>>> {
    if !args.check {
        return Ok(None);
    }
    let named = named_model(args, "--check")?;
    Ok(Some(named.simulator(false).or_usage()?))
}

/// Starts of the multi-start methods when --starts is not given.
const DEFAULT_STARTS: usize = 5;

/// What a record is estimated with: the parameter names, the method, the
/// record length an estimator file was trained and validated on, the
/// signals (the CSV columns) it reads, and the model --check simulates.
pub(super) struct Chosen {
    pub(super) names: Vec<String>,
    pub(super) method: Method,
    pub(super) trained: Option<usize>,
    pub(super) format: csv_records::RecordFormat,
    pub(super) checker: Option<Box<dyn Simulator>>,
    /// With --refine: the refinement of an estimator's estimates, run over
    /// a file's records together.
    pub(super) refiner: Option<twostage::EstimateRefiner>,
    /// The prior's box, which the intervals stay inside.
    pub(super) prior_box: Option<PriorBox>,
    /// With --joint: the joint fit of every record.
    pub(super) joint: Option<twostage::JointFitter>,
}

/// The method chosen on the command line, ready to estimate records.
pub(super) fn method(args: &EstimateArgs) -> Result<Chosen> {
    use twostage_baselines as b;
    refuse_what_does_not_apply(args)?;
    if let Some(path) = &args.estimator {
        let estimator = Estimator::load(path)?;
        let names = estimator.param_names().to_vec();
        let trained = estimator.record_shape().n_samples;
        let format = csv_records::RecordFormat {
            signals: estimator.signal_names(),
            sample_time: estimator.record_shape().sample_time,
        };
        let transforms = estimator.transforms_outputs();
        let family = estimator.input_family().is_some();
        // Read once for the check, the refinement and the joint fit (it
        // is refused above without one of them).
        let given = model_file(args)?;
        let given = given.as_ref();
        let checker = if args.checks() {
            Some(model_of(&estimator, given)?)
        } else {
            None
        };
        let refines = args.refine.is_some();
        let refiner = if refines {
            Some(refinement(&estimator, given, args)?)
        } else {
            None
        };
        let joint = if args.joint {
            Some(joint_fitter(&estimator, given, args)?)
        } else {
            None
        };
        // The joint fit, as a refinement, fits records of any length.
        let refines = refines || args.joint;
        let prior_box = Some((estimator.lower().to_vec(), estimator.upper().to_vec()));
        return Ok(Chosen {
            names,
            format,
            trained: Some(trained),
            checker,
            refiner,
            prior_box,
            joint,
            method: Box::new(move |_, record: &IoData| {
                // The two-stage estimate keeps the estimator's length; a
                // refinement fits a record of any length, from it.
                if let Some(refusal) = estimator.length_refusal(record.n_samples())
                    && !refines
                {
                    return Err(refusal);
                }
                let a = estimator.assess(record).map_err(|e| e.to_string())?;
                // The adaptive intervals have the same level and follow the
                // record; the fixed ones are the fallback. Both were
                // calibrated for the TS estimate, not a refined one.
                Ok(Estimated {
                    distance: a.feature_distance.zip(a.distance_threshold),
                    widths: a.interval_half_widths().map(<[f64]>::to_vec),
                    input: family.then_some(a.input_deviations),
                    theta: a.theta,
                    floored: transforms.then_some(a.floored_samples),
                    ..bare(Vec::new())
                })
            }),
        });
    }
    if let Some(path) = &args.at {
        return given_values(args, path);
    }
    if args.method.as_deref() == Some(OUTPUT_ERROR) {
        return output_error_method(args);
    }
    if let (Some(path), Some(name)) = (&args.model_file, &args.method) {
        let file = twostage::ModelFile::load(path).or_usage()?;
        return Err(usage(format!(
            "method '{name}' is not available for {}: the classic methods exist for the \
             built-in models only; train an estimator with `twostage train --model-file`",
            file.name()
        )));
    }
    let (Some(model), Some(name)) = (&args.model, &args.method) else {
        return Err(usage(
            "give --estimator FILE, --model M --method ekf|ukf|pf|pem|ii|bayes, or --model M \
             --at VALUES.csv --check"
                .into(),
        ));
    };
    let model: BuiltinModel = model.parse().map_err(|e| usage(format!("{e}")))?;
    let simulator = model.build(false)?;
    let names = simulator.param_names().to_vec();
    let format = record_format(simulator.spec());
    let method = ModelProfile::of(model).classic_method(name).or_usage()?;
    let settings = b::MethodSettings {
        initial_covariance: args.p0.unwrap_or(InitialCovariance::Eq6).into(),
        particles: args.particles,
        starts: args.starts.unwrap_or(DEFAULT_STARTS),
        seed: args.seed.unwrap_or(0),
    };
    let estimator = b::classic_estimator(model, method, &settings)?;
    Ok(Chosen {
        names,
        format,
        trained: None,
        checker: check_model(args)?,
        refiner: None,
        prior_box: None,
        joint: None,
        method: Box::new(move |_, record: &IoData| {
            estimator
                .estimate(record)
                .map(|e| bare(e.theta))
                .map_err(|e| e.to_string())
        }),
    })
}
