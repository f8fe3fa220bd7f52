//! `twostage.train`: one training request (`twostage::TrainingRequest`)
//! built from keyword arguments, as the command line's `train` builds it
//! from flags, so the same arguments give the same estimator file.

use std::path::PathBuf;

use numpy::{PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use twostage::{
    ChartArrays, ChartDir, ChartGiven, NamedModel, RecordsRequest, RunSettings, TrainingRequest,
};

use crate::simulator::{PythonProgress, PythonSimulator};
use crate::through_model::named_model;
use crate::{PyEstimator, to_python};

/// Train an estimator. The model is a built-in one (`model`), a model
/// file (`model_file`, or its text as `model_toml`), or, with `simulator`,
/// a Python function simulating the model a source-less model file
/// describes, in batches of `batch_size`. The command line's defaults: the
/// same arguments and seed give the same file as `twostage train`.
/// `auto` searches the design (within `budget_seconds`, or on
/// `budget_sims` simulations with every candidate), as `--auto` does; a
/// model without presets searches anyway. `progress` is called as
/// `progress(event, stage, count)`, and as `progress("note" or "status",
/// message, 0)` for the run's messages.
#[pyfunction]
#[pyo3(signature = (model=None, *, model_file=None, model_toml=None, simulator=None, batch_size=64, preset=None, sims=None, compress=None, fit=None, seed=None, validate=None, certify_within=None, max_validate=None, calibrate=None, alpha=None, progress=None, chart=None, validate_chart=None, calibrate_chart=None, auto=false, budget_seconds=None, budget_sims=None, posterior=None, fix=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn train(
    py: Python<'_>,
    model: Option<&str>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    simulator: Option<Py<PyAny>>,
    batch_size: usize,
    preset: Option<&str>,
    sims: Option<usize>,
    compress: Option<&str>,
    fit: Option<&str>,
    seed: Option<u64>,
    validate: Option<usize>,
    certify_within: Option<f64>,
    max_validate: Option<usize>,
    calibrate: Option<usize>,
    alpha: Option<f64>,
    progress: Option<Py<PyAny>>,
    chart: Option<Bound<'_, PyAny>>,
    validate_chart: Option<Bound<'_, PyAny>>,
    calibrate_chart: Option<Bound<'_, PyAny>>,
    auto: bool,
    budget_seconds: Option<f64>,
    budget_sims: Option<usize>,
    posterior: Option<usize>,
    fix: Option<Bound<'_, pyo3::types::PyDict>>,
) -> PyResult<PyEstimator> {
    let search = twostage::Budget::chosen(auto, budget_seconds, budget_sims).map_err(|e| {
        let name = match (e, budget_seconds) {
            (twostage::BudgetChoiceError::Both, _) => "budget_seconds and budget_sims",
            (_, Some(_)) => "budget_seconds",
            (_, None) => "budget_sims",
        };
        PyValueError::new_err(format!("{name}: {e}"))
    })?;
    let named = match (model, simulator.is_some()) {
        (Some(_), true) => {
            return Err(PyValueError::new_err(
                "a simulator needs a model file without [source] (model_file= or model_toml=) \
                 for its parameter names, priors and signals, not a built-in model",
            ));
        }
        _ => named_model(model, model_file, model_toml)?.ok_or_else(|| {
            PyValueError::new_err(
                "give one of model='benchmark' (a built-in model), model_file='path.toml' or \
                 model_toml='...' (a model file's text)",
            )
        })?,
    };
    let defaults = RunSettings::default();
    let given = |chart: Option<Bound<'_, PyAny>>, name: &str| {
        chart.map(|c| chart_given(&c, name)).transpose()
    };
    let (chart, validate_chart, calibrate_chart) = (
        given(chart, "chart")?,
        given(validate_chart, "validate_chart")?,
        given(calibrate_chart, "calibrate_chart")?,
    );
    let records = match (chart, validate_chart, calibrate_chart) {
        (None, None, None) => RecordsRequest::Simulated,
        (Some(training), validation, calibration) => {
            // A folder's argument may name shards instead of a chart.
            let shards = match &training {
                ChartGiven::Folder(folder) => Some(RecordsRequest::chart(&folder.dir))
                    .filter(|named| matches!(named, RecordsRequest::Shards { .. })),
                ChartGiven::Arrays { .. } => None,
            };
            match shards {
                Some(_) if validation.is_some() || calibration.is_some() => {
                    return Err(PyValueError::new_err(
                        "shards hold their own calibration and validation records: leave out \
                         validate_chart and calibrate_chart",
                    ));
                }
                Some(shards) => shards,
                None => RecordsRequest::Given {
                    training,
                    calibration,
                    validation,
                },
            }
        }
        (None, _, _) => {
            return Err(PyValueError::new_err(
                "validate_chart and calibrate_chart go with chart (a training chart)",
            ));
        }
    };
    let request = TrainingRequest {
        preset: preset.map(str::to_string),
        simulations: sims,
        compress: compress.map(str::to_string),
        fit: fit.map(str::to_string),
        search,
        posterior,
        settings: RunSettings {
            seed,
            calibration: calibrate.unwrap_or(defaults.calibration),
            alpha: alpha.unwrap_or(defaults.alpha),
            ..defaults
        }
        .validation_asked(validate, certify_within, max_validate),
        records,
        fix: fixed_values(fix)?,
    };
    let python = match (&named, simulator) {
        (NamedModel::File(file), Some(function)) => {
            let python = PythonSimulator::new(function, file.spec().clone(), batch_size);
            Some(file.simulator_with(Box::new(python)).map_err(to_python)?)
        }
        (_, Some(_)) => {
            return Err(PyValueError::new_err(
                "a simulator needs a model file without [source] (model_file= or model_toml=)",
            ));
        }
        (_, None) => None,
    };
    let reporter = progress.map(PythonProgress::new);
    let trained = py.detach(|| -> twostage::Result<twostage::Trained> {
        let progress: &dyn twostage::Progress = match &reporter {
            Some(reporter) => reporter,
            None => &twostage::Silent,
        };
        match &python {
            Some(simulator) => request.train_with(&named, simulator.as_ref(), progress),
            None => request.train(&named, progress),
        }
    });
    trained
        .map(|trained| PyEstimator {
            inner: trained.into_estimator(),
        })
        .map_err(to_python)
}

/// A `chart` argument as the request takes it: a folder (a path), or the
/// arrays `(theta [m, q], inputs [m, N, n_u] or None, outputs [m, N, n_y])`,
/// float64.
fn chart_given(chart: &Bound<'_, PyAny>, name: &str) -> PyResult<ChartGiven> {
    if let Ok(dir) = chart.extract::<PathBuf>() {
        return Ok(ChartGiven::Folder(ChartDir::new(dir)));
    }
    let Ok((theta, inputs, outputs)) =
        chart.extract::<(Bound<'_, PyAny>, Option<Bound<'_, PyAny>>, Bound<'_, PyAny>)>()
    else {
        return Err(PyValueError::new_err(format!(
            "{name} is a folder or a tuple (theta [m, q], inputs [m, N, n_u] or None, outputs \
             [m, N, n_y]), not {}",
            chart.get_type().name()?
        )));
    };
    let float64 = |array: &Bound<'_, PyAny>, part: &str| {
        PyValueError::new_err(format!(
            "{name} {part} must be a float64 numpy array (np.asarray({part}, dtype=np.float64)), \
             not {}",
            array
                .getattr("dtype")
                .map_or_else(|_| array.get_type().to_string(), |d| d.to_string())
        ))
    };
    let theta = theta
        .extract::<PyReadonlyArray2<'_, f64>>()
        .map_err(|_| float64(&theta, "theta"))?
        .as_array()
        .to_owned();
    let inputs = inputs
        .map(|u| {
            u.extract::<PyReadonlyArray3<'_, f64>>()
                .map(|a| a.as_array().to_owned())
                .map_err(|_| float64(&u, "inputs"))
        })
        .transpose()?;
    let outputs = outputs
        .extract::<PyReadonlyArray3<'_, f64>>()
        .map_err(|_| float64(&outputs, "outputs"))?
        .as_array()
        .to_owned();
    let label = format!("of {} experiments given as arrays", theta.nrows());
    Ok(ChartGiven::Arrays {
        arrays: std::sync::Arc::new(ChartArrays {
            theta,
            inputs,
            outputs,
        }),
        label,
    })
}

/// `fix={name: value}` as the values held, in the dict's order.
pub(crate) fn fixed_values(
    fix: Option<Bound<'_, pyo3::types::PyDict>>,
) -> PyResult<twostage::models::FixedValues> {
    let mut pairs: Vec<(String, f64)> = Vec::new();
    for (name, value) in fix.iter().flat_map(|d| d.iter()) {
        let name: String = name
            .extract()
            .map_err(|_| PyValueError::new_err(format!("fix: the key {name} is not a str")))?;
        let value: f64 = value.extract().map_err(|_| {
            PyValueError::new_err(format!("fix: {name}'s value {value} is not a number"))
        })?;
        pairs.push((name, value));
    }
    twostage::models::FixedValues::from_pairs(pairs.iter().map(|(n, v)| (n.as_str(), *v)))
        .map_err(|e| PyValueError::new_err(e.to_string()))
}
