//! Through the model, from numpy arrays: check an estimate (or given
//! values) against a record, refine an estimate, and predict a record on a
//! given input; the command line's `estimate --check`, `estimate --refine`,
//! `estimate --at --check` and `simulate --at --input --noiseless`, with
//! the same library calls underneath and so the same numbers.

use std::path::PathBuf;

use ndarray::Axis;
use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use twostage::models::{Conditions, IoData, Simulator, experiment_rng};
use twostage::{
    EstimateRequest, EstimateWith, Estimating, GivenValues, NamedModel, RecordCheck, RecordEstimate,
};

use crate::arrays::{as_batch, non_finite, records};
use crate::to_python;

/// The model named by one of `model` (built-in), `model_file` or
/// `model_toml` (a model file's text), or `None` when none is given.
pub(crate) fn named_model(
    model: Option<&str>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
) -> PyResult<Option<NamedModel>> {
    let named = match (model, model_file, model_toml) {
        (None, None, None) => return Ok(None),
        (Some(name), None, None) => NamedModel::builtin(name),
        (None, Some(path), None) => NamedModel::file(path),
        (None, None, Some(text)) => NamedModel::text(text, "model_toml"),
        _ => {
            return Err(PyValueError::new_err(
                "give one of model= (a built-in model), model_file= or model_toml=, not several",
            ));
        }
    };
    named.map(Some).map_err(to_python)
}

/// One record from `u` [N, n_u] (None without inputs) and `y` [N, n_y]
/// (None: zeros, for a prediction that reads the input only).
pub(crate) fn one_record(
    u: Option<&Bound<'_, PyAny>>,
    y: Option<&Bound<'_, PyAny>>,
    n_inputs: usize,
    n_outputs: usize,
) -> PyResult<IoData> {
    let one = |name: &str, array: Option<&Bound<'_, PyAny>>, width: usize| -> PyResult<_> {
        let (array, single) = records(name, array, width, None)?;
        if !single {
            return Err(PyValueError::new_err(format!(
                "{name} is a batch: give one record [N, {width}] (loop over a batch: each \
                 record runs its own simulations)"
            )));
        }
        let Some(array) = array else {
            return Ok(None);
        };
        let view = as_batch(&array)?;
        let record = view.index_axis(Axis(0), 0);
        if let Some(bad) = non_finite(name, record, 0, true) {
            return Err(PyValueError::new_err(bad));
        }
        Ok(Some(record.to_owned()))
    };
    let inputs = one("u", u, n_inputs)?;
    let outputs = match y {
        Some(_) => one("y", y, n_outputs)?,
        None => None,
    };
    let n = match (&inputs, &outputs) {
        (Some(u), Some(y)) if u.nrows() != y.nrows() => {
            return Err(PyValueError::new_err(format!(
                "u has {} samples and y {}: one record's signals have one length",
                u.nrows(),
                y.nrows()
            )));
        }
        (Some(u), _) => u.nrows(),
        (None, Some(y)) => y.nrows(),
        (None, None) => {
            return Err(PyValueError::new_err(
                "no signal given: pass the record's input u (and its outputs y)",
            ));
        }
    };
    let mut record = IoData::zeros(n, n_inputs, n_outputs);
    if let Some(u) = &inputs {
        for (j, column) in u.columns().into_iter().enumerate() {
            record
                .input_mut(j)
                .iter_mut()
                .zip(column)
                .for_each(|(s, v)| *s = *v);
        }
    }
    if let Some(y) = &outputs {
        for (j, column) in y.columns().into_iter().enumerate() {
            record
                .output_mut(j)
                .iter_mut()
                .zip(column)
                .for_each(|(s, v)| *s = *v);
        }
    }
    Ok(record)
}

/// A parameter vector of as many values as the model has parameters
/// (`names`), finite.
pub(crate) fn parameters(theta: &[f64], names: &[String]) -> PyResult<()> {
    if theta.len() != names.len() {
        return Err(PyValueError::new_err(format!(
            "theta has {} values, the model has {} parameters ({})",
            theta.len(),
            names.len(),
            names.join(", ")
        )));
    }
    if let Some((name, v)) = names.iter().zip(theta).find(|(_, v)| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "theta's {name} is {v}: give finite values"
        )));
    }
    Ok(())
}

/// A record's outputs [N, n_y] as numpy.
pub(crate) fn outputs<'py>(py: Python<'py>, record: &IoData) -> Bound<'py, PyAny> {
    record
        .outputs()
        .as_standard_layout()
        .into_owned()
        .into_pyarray(py)
        .into_any()
}

/// A record's inputs [N, n_u] as numpy.
pub(crate) fn inputs<'py>(py: Python<'py>, record: &IoData) -> Bound<'py, PyAny> {
    record
        .inputs()
        .as_standard_layout()
        .into_owned()
        .into_pyarray(py)
        .into_any()
}

/// A check as the dict the Python layer returns: the command line's check
/// columns, per output as arrays, and the noise-free response.
/// An estimate with its own interval into `dict`: `theta`, `half_widths`
/// (None, with `interval_error` saying why, where it has none) and
/// `correlation` [q, q] or None, as `refine` and `joint` return them.
pub(crate) fn set_estimate(
    py: Python<'_>,
    dict: &Bound<'_, PyDict>,
    theta: Vec<f64>,
    half_widths: Result<Vec<f64>, String>,
    correlation: Option<Vec<f64>>,
) -> PyResult<()> {
    let q = theta.len();
    dict.set_item("theta", theta.into_pyarray(py))?;
    match half_widths {
        Ok(w) => {
            dict.set_item("half_widths", w.into_pyarray(py))?;
            dict.set_item("interval_error", py.None())?;
        }
        Err(e) => {
            dict.set_item("half_widths", py.None())?;
            dict.set_item("interval_error", e)?;
        }
    }
    match correlation {
        Some(r) => dict.set_item(
            "correlation",
            ndarray::Array2::from_shape_vec((q, q), r)
                .map_err(|e| PyValueError::new_err(format!("array shape: {e}")))?
                .into_pyarray(py),
        ),
        None => dict.set_item("correlation", py.None()),
    }
}

pub(crate) fn check_dict<'py>(
    py: Python<'py>,
    check: &RecordCheck,
) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("rms", check.rms.clone().into_pyarray(py))?;
    dict.set_item("fit_percent", check.fit_percent.clone().into_pyarray(py))?;
    dict.set_item("check_tail_probability", check.tail_probability)?;
    dict.set_item(
        "check_improvement_tail_probability",
        check.improvement_tail_probability,
    )?;
    dict.set_item(
        "check_best_fit_tail_probability",
        check.best_fit_tail_probability,
    )?;
    dict.set_item("check_runs", check.reference_runs)?;
    dict.set_item("model_consistent", check.model_consistent())?;
    dict.set_item("loss_over_best", check.loss_ratio)?;
    dict.set_item("optima", check.optima)?;
    dict.set_item("runner_up_over_best", check.runner_up_ratio)?;
    dict.set_item("explained", check.explained())?;
    dict.set_item(
        "input_as_trained",
        check
            .input_shared
            .then_some(check.input_differs_at.is_none()),
    )?;
    dict.set_item(
        "best_fit_percent",
        check.best_fit_percent.clone().into_pyarray(py),
    )?;
    dict.set_item("simulated", outputs(py, &check.simulated))?;
    Ok(dict)
}

/// A request prepared, its error as Python's: what it was for and why.
pub(crate) fn prepared(request: EstimateRequest) -> PyResult<Estimating> {
    request.prepare().map_err(|e| match &e.error {
        // Named as the keyword that would accept them, before the
        // request's words.
        twostage::RequestProblem::OutsidePrior { .. } => PyValueError::new_err(format!(
            "theta without allow_outside_prior=True: {}",
            e.error
        )),
        _ => PyValueError::new_err(e.to_string()),
    })
}

/// One record through a prepared request, without the GIL: its row, or
/// why it has none.
pub(crate) fn one_row(
    py: Python<'_>,
    estimating: &Estimating,
    record: IoData,
) -> PyResult<RecordEstimate> {
    let estimates = py.detach(|| {
        estimating.estimate_each(
            vec![("0".into(), Ok(record))],
            &|_| "the record".into(),
            &twostage::Silent,
        )
    });
    let (_, outcome) = estimates
        .rows
        .into_iter()
        .next()
        .unwrap_or_else(|| unreachable!("one record, one row"));
    outcome
        .map(|(_, row)| row)
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The check a row carries, as its dict; why it could not simulate, as
/// Python's error.
pub(crate) fn checked_dict<'py>(
    py: Python<'py>,
    row: &RecordEstimate,
) -> PyResult<Bound<'py, PyDict>> {
    match &row.check {
        Some(Ok(check)) => check_dict(py, check),
        Some(Err(e)) => Err(PyValueError::new_err(format!(
            "the check could not simulate: {e}"
        ))),
        None => unreachable!("a request that checks gives every row a check"),
    }
}

/// The check's settings as the keyword arguments give them.
pub(crate) fn check_settings(
    sims: Option<usize>,
    score_from: usize,
    score_to: Option<usize>,
) -> twostage::CheckSettings {
    twostage::CheckSettings {
        runs: sims.unwrap_or(twostage::DEFAULT_CHECK_RUNS),
        score_from,
        score_to,
    }
}

/// Check given values against a record (`twostage estimate --at VALUES
/// --check`): a dict of the check's columns, the noise-free response in
/// `simulated`.
#[pyfunction]
#[pyo3(signature = (theta, u, y, *, model=None, model_file=None, model_toml=None, sims=None, seed=0, allow_outside_prior=false, score_from=0, score_to=None, prior_starts=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn check_values<'py>(
    py: Python<'py>,
    theta: Vec<f64>,
    u: Option<&Bound<'py, PyAny>>,
    y: &Bound<'py, PyAny>,
    model: Option<&str>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    sims: Option<usize>,
    seed: u64,
    allow_outside_prior: bool,
    score_from: usize,
    score_to: Option<usize>,
    prior_starts: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let named = named_model(model, model_file, model_toml)?.ok_or_else(|| {
        PyValueError::new_err(
            "the check simulates the model: give model=, model_file= or model_toml=",
        )
    })?;
    let sim = named.simulator().map_err(to_python)?;
    let spec = sim.spec();
    let record = one_record(
        u,
        Some(y),
        spec.input_names().len(),
        spec.output_names().len(),
    )?;
    parameters(&theta, sim.spec().param_names())?;
    let given = GivenValues::new(vec![("0".into(), theta)], "theta")
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let estimating = prepared(
        EstimateRequest::new(EstimateWith::Given(given))
            .model(Some(named))
            .allow_outside_prior(allow_outside_prior)
            .check_records(true)
            .check_settings(check_settings(sims, score_from, score_to))
            .seed(seed)
            .prior_starts(prior_starts),
    )?;
    checked_dict(py, &one_row(py, &estimating, record)?)
}

/// The model's record at `theta` on the input `u` (`twostage simulate --at
/// --input`), noise-free unless `noiseless` is False (then the noise of
/// experiment `experiment` of `seed`, as row `experiment` of the command's
/// estimates): `(u [N, n_u], y [N, n_y])`. `u` None runs the model's own
/// input design.
#[pyfunction]
#[pyo3(signature = (theta, u=None, *, model=None, model_file=None, model_toml=None, noiseless=true, seed=0, experiment=0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn predict<'py>(
    py: Python<'py>,
    theta: Vec<f64>,
    u: Option<&Bound<'py, PyAny>>,
    model: Option<&str>,
    model_file: Option<PathBuf>,
    model_toml: Option<&str>,
    noiseless: bool,
    seed: u64,
    experiment: u64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let named = named_model(model, model_file, model_toml)?.ok_or_else(|| {
        PyValueError::new_err(
            "predict simulates the model: give model=, model_file= or model_toml=",
        )
    })?;
    let sim = named.simulator().map_err(to_python)?;
    let spec = sim.spec();
    parameters(&theta, sim.spec().param_names())?;
    let given = match u {
        Some(_) => Some(one_record(
            u,
            None,
            spec.input_names().len(),
            spec.output_names().len(),
        )?),
        None => None,
    };
    let conditions = Conditions {
        noiseless,
        input: given.as_ref(),
    };
    let mut record = IoData::default();
    py.detach(|| {
        sim.simulate_under(
            &theta,
            &mut experiment_rng(seed, experiment),
            conditions,
            &mut record,
        )
    })
    .map_err(|e| PyValueError::new_err(format!("simulating {}: {e}", spec.name())))?;
    Ok((inputs(py, &record), outputs(py, &record)))
}
