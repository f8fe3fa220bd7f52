//! Input checks shared by the regressors.

use ndarray::ArrayView2;

use crate::error::{FitError, Result};

/// Check that `x` (samples x features) and `y` (samples x targets) agree
/// and hold only finite values.
pub(crate) fn training_data(x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<()> {
    if x.nrows() != y.nrows() {
        return Err(FitError::ShapeMismatch(format!(
            "{} feature rows but {} target rows",
            x.nrows(),
            y.nrows()
        )));
    }
    if x.ncols() == 0 || y.ncols() == 0 {
        return Err(FitError::ShapeMismatch(format!(
            "{} features and {} targets: both must be at least 1",
            x.ncols(),
            y.ncols()
        )));
    }
    finite(x, "features")?;
    finite(y, "targets")
}

pub(crate) fn finite(a: ArrayView2<'_, f64>, what: &'static str) -> Result<()> {
    for ((row, col), &value) in a.indexed_iter() {
        if !value.is_finite() {
            return Err(FitError::NonFinite {
                what,
                row,
                col,
                value,
            });
        }
    }
    Ok(())
}

pub(crate) fn row_lengths(x: &[f64], out: &[f64], n_in: usize, n_out: usize) -> Result<()> {
    if x.len() != n_in || out.len() != n_out {
        return Err(FitError::ShapeMismatch(format!(
            "the model maps {n_in} features to {n_out} targets; got {} features and an \
             output buffer of {}",
            x.len(),
            out.len()
        )));
    }
    Ok(())
}
