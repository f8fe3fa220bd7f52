//! `Estimator.joint`'s dict: one estimate of a plant from several
//! records, as the command line's `estimate --joint` gives it (both make
//! the same estimate request).

use numpy::IntoPyArray;
use pyo3::prelude::*;
use twostage::JointOfRecords;

/// The dict `Estimator.joint` returns: `theta`; `half_widths` (None, with
/// `interval_error` saying why, where the records do not determine a
/// parameter); `correlation` [q, q] or None; `stop`; `optima`;
/// `runner_up_over_best` (None with one optimum); `pooled`, the two-stage
/// estimates pooled; `fitted`, the indices of the records fitted, and
/// `fit_percent`, each one's fit at the joint estimate; `left_out`, pairs
/// of an index and why; `disagreeing`, the indices of records whose
/// two-stage estimates lie beyond their intervals from the others';
/// `between_sd`, per parameter the sd of the records' own best fits about
/// the joint one beyond their noise (None with fewer than two records
/// that determine every parameter), and `mismatch_sets_width`, per
/// parameter whether that scatter, beyond chance and above a record's own
/// sd, sets the widths (the joint interval includes it); `per_record`,
/// per parameter whether it belongs to each record (`per_record = true` in
/// the model file: NaN in `theta`), and `records_theta` [fitted, q] and
/// `records_half_widths` (or None), each fitted record's whole estimate.
pub(crate) fn joint_dict(
    py: Python<'_>,
    joint: JointOfRecords,
) -> PyResult<Bound<'_, pyo3::types::PyDict>> {
    let dict = pyo3::types::PyDict::new(py);
    crate::through_model::set_estimate(
        py,
        &dict,
        joint.theta,
        joint.half_widths.map_err(|e| e.to_string()),
        joint.correlation,
    )?;
    dict.set_item("stop", joint.stop.name())?;
    dict.set_item("optima", joint.optima)?;
    dict.set_item("runner_up_over_best", joint.runner_up_ratio)?;
    dict.set_item("pooled", joint.pooled.into_pyarray(py))?;
    let (fitted, fits): (Vec<usize>, Vec<f64>) = joint.fitted.into_iter().unzip();
    dict.set_item("fitted", fitted)?;
    dict.set_item("fit_percent", fits.into_pyarray(py))?;
    let left_out: Vec<(usize, String)> = joint
        .left_out
        .into_iter()
        .map(|(i, why)| (i, why.to_string()))
        .collect();
    dict.set_item("left_out", left_out)?;
    dict.set_item("disagreeing", joint.disagreeing)?;
    let (between, wide) = joint
        .between
        .map(|b| {
            let wide = b.mismatch_sets_width();
            (b.sd.into_pyarray(py), wide)
        })
        .unzip();
    dict.set_item("between_sd", between)?;
    dict.set_item("mismatch_sets_width", wide)?;
    let q = joint.per_record.len();
    dict.set_item("per_record", joint.per_record)?;
    let fitted = joint.records.len();
    let (thetas, widths): (Vec<Vec<f64>>, Vec<Option<Vec<f64>>>) = joint
        .records
        .into_iter()
        .map(|r| (r.theta, r.half_widths))
        .unzip();
    let matrix = |rows: Vec<Vec<f64>>| {
        numpy::ndarray::Array2::from_shape_vec((fitted, q), rows.concat())
            .map(|a| a.into_pyarray(py))
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))
    };
    dict.set_item("records_theta", matrix(thetas)?)?;
    let widths: Option<Vec<Vec<f64>>> = widths.into_iter().collect();
    dict.set_item("records_half_widths", widths.map(matrix).transpose()?)?;
    Ok(dict)
}
