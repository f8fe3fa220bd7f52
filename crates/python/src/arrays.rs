//! numpy arrays in and out: records as batch views, checked for
//! finiteness by index, and rows of results as arrays.

use ndarray::{ArrayView2, ArrayView3, Axis, Ix3};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// One record `[N, n]` or a batch `[b, N, n]` of float64, as a batch view,
/// and whether it was one record. `n` must be `width`; `None` stands for a
/// model without that kind of signal (`width == 0`).
pub(crate) fn records<'a>(
    name: &str,
    array: Option<&'a Bound<'_, PyAny>>,
    width: usize,
    batch: Option<usize>,
) -> PyResult<(Option<numpy::PyReadonlyArrayDyn<'a, f64>>, bool)> {
    let Some(array) = array else {
        if width == 0 {
            return Ok((None, batch.is_none()));
        }
        return Err(PyValueError::new_err(format!(
            "{name} is None, but the estimator's model has {width} such signal(s): pass a \
             float64 array [N, {width}] or [b, N, {width}]"
        )));
    };
    let Ok(untyped) = array.cast::<PyUntypedArray>() else {
        return Err(PyValueError::new_err(format!(
            "{name} must be a numpy array (float64 [N, {width}] or [b, N, {width}]), not {}",
            array.get_type().name()?
        )));
    };
    let Ok(typed) = array.cast::<PyArrayDyn<f64>>() else {
        return Err(PyValueError::new_err(format!(
            "{name} has dtype {}, not float64: convert it with np.asarray({name}, \
             dtype=np.float64) (the estimator never casts on its own)",
            untyped.dtype()
        )));
    };
    let shape = untyped.shape().to_vec();
    let single = match shape.len() {
        2 => true,
        3 => false,
        _ => {
            return Err(PyValueError::new_err(format!(
                "{name} has shape {shape:?}: give one record [N, {width}] or a batch \
                 [b, N, {width}]"
            )));
        }
    };
    if shape[shape.len() - 1] != width {
        return Err(PyValueError::new_err(format!(
            "{name} has shape {shape:?}: its last axis must be the model's {width} signal(s)"
        )));
    }
    if let Some(b) = batch
        && (single || shape[0] != b)
    {
        return Err(PyValueError::new_err(format!(
            "{name} has shape {shape:?}, the other array holds {b} record(s): give both as \
             one record or both as batches of the same size"
        )));
    }
    let readonly = typed.try_readonly().map_err(|e| {
        PyValueError::new_err(format!("{name} cannot be read while it is written: {e}"))
    })?;
    Ok((Some(readonly), single))
}

/// A `[N, n]` or `[b, N, n]` view as `[b, N, n]`.
pub(crate) fn as_batch<'a>(
    array: &'a numpy::PyReadonlyArrayDyn<'_, f64>,
) -> PyResult<ArrayView3<'a, f64>> {
    let view = array.as_array();
    let view = if view.ndim() == 2 {
        view.insert_axis(Axis(0))
    } else {
        view
    };
    view.into_dimensionality::<Ix3>().map_err(shape_error)
}

pub(crate) fn shape_error(e: ndarray::ShapeError) -> PyErr {
    PyValueError::new_err(format!("array shape: {e}"))
}

/// The first sample of record `k` of `name` that is not finite, as the
/// message naming its index in the caller's array.
pub(crate) fn non_finite(
    name: &str,
    record: ArrayView2<'_, f64>,
    k: usize,
    single: bool,
) -> Option<String> {
    if let Some(flat) = record.as_slice()
        && flat.iter().all(|v| v.is_finite())
    {
        return None;
    }
    let ((t, j), value) = record.indexed_iter().find(|(_, v)| !v.is_finite())?;
    let index = if single {
        format!("[{t}, {j}]")
    } else {
        format!("[{k}, {t}, {j}]")
    };
    Some(format!(
        "{name}{index} is {value}: records must be finite (drop or repair that sample)"
    ))
}

/// `values` (`[b, width]` row-major) as a numpy array `[width]` for one record
/// or [b, width] for a batch.
pub(crate) fn rows(
    py: Python<'_>,
    values: Vec<f64>,
    width: usize,
    single: bool,
) -> Bound<'_, PyAny> {
    if single {
        ndarray::Array1::from_vec(values)
            .into_pyarray(py)
            .into_any()
    } else {
        let b = values.len() / width.max(1);
        ndarray::Array2::from_shape_vec((b, width), values)
            .map(|a| a.into_pyarray(py).into_any())
            .unwrap_or_else(|_| unreachable!("b rows of width values"))
    }
}
