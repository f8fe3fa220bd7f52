//! What the estimator does through its model, each one estimate request
//! (`twostage::EstimateRequest`) as the command line's `estimate` makes
//! it, or the validation run `twostage validate` makes: so the numbers
//! are the command line's, bit for bit.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use twostage::models::IoData;
use twostage::sources::csv_rows::DataFileError;
use twostage::{EstimateRequest, EstimateWith};

use crate::arrays::shape_error;
use crate::simulator::PythonProgress;
use crate::through_model::{
    check_settings, checked_dict, named_model, one_record, one_row, prepared,
};
use crate::{joint, through_model, to_python};

#[allow(clippy::too_many_arguments)]
pub(crate) fn check<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    u: Option<&Bound<'py, PyAny>>,
    y: &Bound<'py, PyAny>,
    theta: Option<Vec<f64>>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    sims: Option<usize>,
    seed: u64,
    score_from: usize,
    score_to: Option<usize>,
    prior_starts: Option<usize>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let named = named_model(None, model_file, model_toml)?;
    let shape = estimator.record_shape();
    let record = one_record(u, Some(y), shape.n_inputs, shape.n_outputs)?;
    let with = match theta {
        // The estimator's own estimate, its interval's corners among
        // the search's starts.
        None => EstimateWith::Estimator(Box::new(estimator.clone())),
        Some(theta) => {
            through_model::parameters(&theta, estimator.param_names())?;
            let values = twostage::GivenValues::new(vec![("0".into(), theta)], "theta")
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            EstimateWith::GivenOfEstimator {
                values,
                estimator: Box::new(estimator.clone()),
            }
        }
    };
    let estimating = prepared(
        EstimateRequest::new(with)
            .model(named)
            .check_records(true)
            .check_settings(check_settings(sims, score_from, score_to))
            .seed(seed)
            .prior_starts(prior_starts),
    )?;
    checked_dict(py, &one_row(py, &estimating, record)?)
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(crate) fn validate<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    sims: Option<usize>,
    gamma: Option<f64>,
    delta: Option<f64>,
    seed: Option<u64>,
    target_rmse: Option<f64>,
    max_sims: Option<usize>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    String,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Option<(bool, f64)>,
)> {
    let named = named_model(None, model_file, model_toml)?;
    let defaults = twostage::ValidationPlan::default();
    let plan = twostage::ValidationPlan {
        sims,
        gamma,
        delta: delta.unwrap_or(defaults.delta),
        seed: seed.unwrap_or(defaults.seed),
        target_rmse,
        max_sims: max_sims.unwrap_or(defaults.max_sims),
    };
    let reporter = progress.map(PythonProgress::new);
    let run = py
        .detach(|| {
            let progress: &dyn twostage::Progress = match &reporter {
                Some(reporter) => reporter,
                None => &twostage::Silent,
            };
            twostage::validate_trained(estimator, named.as_ref(), &plan, progress)
        })
        .map_err(to_python)?;
    let report = run
        .report_json()
        .map(|json| json.to_string())
        .map_err(|e| PyValueError::new_err(format!("validation report: {e}")))?;
    let q = estimator.param_names().len();
    let table = |values: Vec<f64>| -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        Ok(ndarray::Array2::from_shape_vec((run.records, q), values)
            .map_err(shape_error)?
            .into_dyn()
            .into_pyarray(py))
    };
    let target = run.target.map(|t| match t {
        twostage::TargetRmse::Met { ratio } => (true, ratio),
        twostage::TargetRmse::NotMet { ratio } => (false, ratio),
    });
    Ok((report, table(run.truth)?, table(run.estimates)?, target))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn joint<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    records: Vec<(Option<Bound<'py, PyAny>>, Bound<'py, PyAny>)>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    prior_starts: Option<usize>,
    seed: u64,
    fix: twostage::models::FixedValues,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let named = named_model(None, model_file, model_toml)?;
    let estimating = prepared(
        EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
            .model(named)
            .joint(true)
            .seed(seed)
            .prior_starts(prior_starts)
            .fix(fix),
    )?;
    let shape = estimator.record_shape();
    let records: Vec<(String, IoData)> = records
        .iter()
        .enumerate()
        .map(|(k, (u, y))| {
            one_record(u.as_ref(), Some(y), shape.n_inputs, shape.n_outputs)
                .map(|record| (k.to_string(), record))
                .map_err(|e| PyValueError::new_err(format!("records[{k}]: {e}")))
        })
        .collect::<PyResult<_>>()?;
    let joint = py.detach(|| {
        let batch = twostage::RecordBatch::indexed("records", records);
        let joint = estimating.run(
            [Ok(batch)],
            &twostage::Silent,
            |_, estimates| match estimates.rows.into_iter().find_map(|(_, o)| o.err()) {
                Some(e) => Err(e.to_string()),
                None => Ok(()),
            },
        )?;
        match joint.map(|joint| joint.fit) {
            Some(Ok((joint, _))) => Ok(joint),
            Some(Err(e)) => Err(format!("the joint fit failed: {e}")),
            None => unreachable!("the request asks for the joint fit of its records"),
        }
    });
    joint::joint_dict(py, joint.map_err(PyValueError::new_err)?)
}

pub(crate) fn refine<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    u: Option<&Bound<'py, PyAny>>,
    y: &Bound<'py, PyAny>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let named = named_model(None, model_file, model_toml)?;
    let estimating = prepared(
        EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
            .model(named)
            .refine(Some(twostage::RefineWhich::All)),
    )?;
    let shape = estimator.record_shape();
    let record = one_record(u, Some(y), shape.n_inputs, shape.n_outputs)?;
    let row = one_row(py, &estimating, record)?;
    let refined = match row.refinement {
        Some(twostage::RefineOutcome::Done(refined)) => refined,
        Some(twostage::RefineOutcome::Failed(e)) => {
            return Err(PyValueError::new_err(format!(
                "the refinement failed ({e}); the two-stage estimate stands"
            )));
        }
        None => unreachable!("a request that refines gives every row a refinement"),
    };
    let half_widths = match (refined.interval_failure, row.half_widths) {
        (Some(why), _) => Err(why.to_string()),
        (None, Some(widths)) => Ok(widths),
        (None, None) => Err("the refinement gave no interval".into()),
    };
    let (stop, optima) = match refined.by {
        twostage::RefinedBy::PosteriorMean => (None, None),
        twostage::RefinedBy::Descent { stop, optima } => (Some(stop), optima),
    };
    let dict = pyo3::types::PyDict::new(py);
    through_model::set_estimate(py, &dict, row.theta, half_widths, refined.correlation)?;
    dict.set_item("stop", stop.map(|s| s.name()))?;
    dict.set_item("optima", optima.map(|o| o.count))?;
    dict.set_item(
        "runner_up_over_best",
        optima.and_then(|o| o.runner_up_over_best),
    )?;
    Ok(dict)
}

/// What `Estimator.estimate_records` returns before the Python layer
/// reads it: the rows as JSON, the records that failed (experiment and
/// why), and what `refine="auto"` chose (explained, checked, and each
/// refined experiment with its reason).
type Table = (
    String,
    Vec<(String, String)>,
    Option<(usize, usize, Vec<(String, String)>)>,
);

/// Every record of `records` (pairs `(u, y)`, named `experiments` or by
/// their index) through one estimate request, as `twostage estimate`
/// makes it from the same flags: the rows as its `--format json` writes
/// them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn estimate_records<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    records: Vec<(Option<Bound<'py, PyAny>>, Bound<'py, PyAny>)>,
    experiments: Option<Vec<String>>,
    check: bool,
    refine: Option<&str>,
    refine_below_fit: Option<f64>,
    joint: bool,
    window: Option<usize>,
    every: Option<usize>,
    correlation: bool,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    sims: Option<usize>,
    score_from: usize,
    score_to: Option<usize>,
    prior_starts: Option<usize>,
    seed: u64,
    progress: Option<Py<PyAny>>,
    fix: twostage::models::FixedValues,
) -> PyResult<Table> {
    let ids = match experiments {
        Some(ids) if ids.len() != records.len() => {
            return Err(PyValueError::new_err(format!(
                "experiments has {} names for {} records: give one per record",
                ids.len(),
                records.len()
            )));
        }
        Some(ids) => ids,
        None => (0..records.len()).map(|k| k.to_string()).collect(),
    };
    let refine = twostage::RefineWhich::chosen(refine, refine_below_fit).map_err(|e| match e {
        twostage::RefineChoiceError::Unknown(_) => PyValueError::new_err(format!("refine: {e}")),
        twostage::RefineChoiceError::BelowFitWithoutAuto => {
            PyValueError::new_err(format!("refine_below_fit: {e}"))
        }
    })?;
    if every.is_some() && window.is_none() {
        return Err(PyValueError::new_err("every needs window=N: give both"));
    }
    let estimating = prepared(
        EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
            .model(named_model(None, model_file, model_toml)?)
            .check_records(check)
            .check_settings(check_settings(sims, score_from, score_to))
            .refine(refine)
            .joint(joint)
            .windows(window.map(|length| twostage::Windows {
                length,
                every: every.unwrap_or(length),
            }))
            .seed(seed)
            .prior_starts(prior_starts)
            .fix(fix),
    )?;
    let shape = estimator.record_shape();
    let records: Vec<(String, Result<IoData, DataFileError>)> = records
        .iter()
        .zip(ids)
        .enumerate()
        .map(|(k, ((u, y), id))| {
            one_record(u.as_ref(), Some(y), shape.n_inputs, shape.n_outputs)
                .map(|record| (id, Ok(record)))
                .map_err(|e| PyValueError::new_err(format!("records[{k}]: {e}")))
        })
        .collect::<PyResult<_>>()?;
    let reporter = progress.map(PythonProgress::new);
    let (rows, failed, auto) = py.detach(|| {
        let progress: &dyn twostage::Progress = match &reporter {
            Some(reporter) => reporter,
            None => &twostage::Silent,
        };
        let mut rows = Vec::new();
        let mut failed = Vec::new();
        let mut auto = None;
        let batch = twostage::RecordBatch {
            source: "records".into(),
            records,
            place: twostage::RecordPlace::Experiment,
        };
        let joint = estimating.run([Ok(batch)], progress, |_, estimates| {
            auto = estimates.auto.as_ref().map(|auto| {
                let refined = auto
                    .groups(&estimates.rows)
                    .into_iter()
                    .flat_map(|(reason, ids)| {
                        ids.into_iter()
                            .map(move |id| (id.to_string(), reason.describe().to_string()))
                    })
                    .collect();
                (auto.explained, auto.checked, refined)
            });
            for (id, outcome) in estimates.rows {
                match outcome {
                    Ok((_, row)) => rows.push((id, row)),
                    Err(why) => failed.push((id, why.to_string())),
                }
            }
            Ok::<(), std::convert::Infallible>(())
        });
        match joint {
            Ok(Some(joint)) => {
                // The rows so far are the gathered records', in their order.
                joint.widen(rows.iter_mut().map(|(_, row)| row));
                match joint.rows() {
                    Ok(joint_rows) => rows.extend(joint_rows),
                    Err(why) => {
                        failed.push(("joint".into(), format!("the joint fit failed: {why}")));
                    }
                }
            }
            Ok(None) => {}
            Err(never) => match never {},
        }
        (rows, failed, auto)
    });
    let json = serde_json::to_string(&estimating.json(&rows, correlation))
        .map_err(|e| PyValueError::new_err(format!("the rows as JSON: {e}")))?;
    Ok((json, failed, auto))
}

/// A file's records read as `twostage estimate` reads them for
/// `estimator` (the long format, its signals' columns in any order, a
/// `time` column checked): `(experiment, u [N, n_u], y [N, n_y])` for each
/// record read, and `(experiment, why)` for each that could not be.
#[allow(clippy::type_complexity)]
pub(crate) fn read_records<'py>(
    estimator: &twostage::Estimator,
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(
    Vec<(String, Bound<'py, PyAny>, Bound<'py, PyAny>)>,
    Vec<(String, String)>,
)> {
    let shape = estimator.record_shape();
    let signals = estimator.signal_names();
    let format = twostage::sources::record_file::RecordFormat {
        inputs: signals.inputs,
        outputs: signals.outputs,
        sample_time: shape.sample_time,
    };
    let read = py
        .detach(|| twostage::sources::record_file::read(&path, &format))
        .map_err(|e| {
            // A file that opens but is no record file (its header, a row)
            // is the caller's data, not the system's: ValueError, with
            // the row named as in every other message.
            if e.row.is_some() {
                pyo3::exceptions::PyValueError::new_err(e.to_string())
            } else {
                pyo3::exceptions::PyOSError::new_err(e.to_string())
            }
        })?;
    let mut records = Vec::new();
    let mut failed = Vec::new();
    for r in read {
        match r.record {
            Ok(record) => records.push((
                r.id,
                through_model::inputs(py, &record),
                through_model::outputs(py, &record),
            )),
            Err(why) => failed.push((r.id, why.to_string())),
        }
    }
    Ok((records, failed))
}
