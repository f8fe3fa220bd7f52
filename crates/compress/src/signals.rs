//! Checks and copies shared by the compressors.

use ndarray::{ArrayView1, ArrayView2};

use crate::error::{CompressError, Result};

/// The checks every least-squares compressor starts with: the feature
/// buffer, the record's shapes and values, and its length against the
/// `needed` samples of the structure. Returns the number of samples N.
#[allow(clippy::too_many_arguments)] // the compressor's whole shape, spelled out
pub(crate) fn check_record(
    inputs: ArrayView2<'_, f64>,
    outputs: ArrayView2<'_, f64>,
    n_inputs: usize,
    n_outputs: usize,
    alpha_len: usize,
    n_features: usize,
    needed: usize,
    structure: &dyn std::fmt::Display,
) -> Result<usize> {
    check_buffer(alpha_len, n_features)?;
    let n = check(inputs, outputs, n_inputs, n_outputs)?;
    if n < needed {
        return Err(CompressError::RecordTooShort {
            n_samples: n,
            needed,
            structure: structure.to_string(),
        });
    }
    Ok(n)
}

/// The checks of a compressor fitted to records of exactly `n_samples`
/// samples (output PCA, raw record): the feature buffer, the record's
/// shapes and values, and its length.
#[allow(clippy::too_many_arguments)] // the compressor's whole shape, spelled out
pub(crate) fn check_fixed_record(
    inputs: ArrayView2<'_, f64>,
    outputs: ArrayView2<'_, f64>,
    n_inputs: usize,
    n_outputs: usize,
    n_samples: usize,
    alpha_len: usize,
    n_features: usize,
    structure: &dyn std::fmt::Display,
) -> Result<()> {
    check_buffer(alpha_len, n_features)?;
    let n = check(inputs, outputs, n_inputs, n_outputs)?;
    if n != n_samples {
        return Err(CompressError::FixedLength {
            expected: n_samples,
            got: n,
            structure: structure.to_string(),
        });
    }
    Ok(())
}

/// The feature buffer has one slot per feature.
fn check_buffer(alpha_len: usize, n_features: usize) -> Result<()> {
    if alpha_len == n_features {
        Ok(())
    } else {
        Err(CompressError::BufferLength {
            expected: n_features,
            got: alpha_len,
        })
    }
}

/// Check shapes, lengths and finiteness; return the number of samples.
pub(crate) fn check(
    inputs: ArrayView2<'_, f64>,
    outputs: ArrayView2<'_, f64>,
    n_inputs: usize,
    n_outputs: usize,
) -> Result<usize> {
    if inputs.ncols() != n_inputs || outputs.ncols() != n_outputs {
        return Err(CompressError::ShapeMismatch {
            inputs: n_inputs,
            outputs: n_outputs,
            got_inputs: inputs.ncols(),
            got_outputs: outputs.ncols(),
        });
    }
    if inputs.nrows() != outputs.nrows() {
        return Err(CompressError::LengthMismatch {
            inputs: inputs.nrows(),
            outputs: outputs.nrows(),
        });
    }
    for (j, column) in inputs.columns().into_iter().enumerate() {
        check_finite(column, || name("u", j, n_inputs))?;
    }
    for (j, column) in outputs.columns().into_iter().enumerate() {
        check_finite(column, || name("y", j, n_outputs))?;
    }
    Ok(inputs.nrows())
}

fn check_finite(column: ArrayView1<'_, f64>, name: impl Fn() -> String) -> Result<()> {
    match column.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(CompressError::NonFinite {
            signal: name(),
            index,
            value: column[index],
        }),
    }
}

/// `u`/`y` for single signals, `u1`, `u2`, ... when there are several.
pub(crate) fn name(prefix: &str, j: usize, count: usize) -> String {
    if count == 1 {
        prefix.to_string()
    } else {
        format!("{prefix}{}", j + 1)
    }
}

/// Copy `src[start..start + dst.len()]` into `dst`.
pub(crate) fn copy_window(dst: &mut [f64], src: ArrayView1<'_, f64>, start: usize) {
    match src.as_slice() {
        Some(s) => dst.copy_from_slice(&s[start..start + dst.len()]),
        None => {
            for (d, v) in dst.iter_mut().zip(src.iter().skip(start)) {
                *d = *v;
            }
        }
    }
}

/// Why a signal makes regressors rank deficient, if it is the obvious reason.
pub(crate) fn degenerate(column: ArrayView1<'_, f64>, name: &str) -> Option<String> {
    let first = *column.iter().next()?;
    let spread = column.iter().fold(0.0f64, |m, v| m.max((v - first).abs()));
    let scale = column.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 {
        Some(format!(
            "{name} is zero over the whole record: there is nothing to fit"
        ))
    } else if spread <= 1e-12 * scale {
        Some(format!(
            "{name} is constant ({first}) over the record: it does not excite the \
             system; use a varying signal"
        ))
    } else {
        diverging(column, name)
    }
}

/// A signal that grows by many orders of magnitude from the start of the
/// record to its end came from an unstable system (or is corrupted); its
/// regressors then span nothing but the growing mode.
fn diverging(column: ArrayView1<'_, f64>, name: &str) -> Option<String> {
    let n = column.len();
    let tenth = (n / 10).max(1);
    let peak = |range: std::ops::Range<usize>| {
        column
            .iter()
            .skip(range.start)
            .take(range.len())
            .fold(0.0f64, |m, v| m.max(v.abs()))
    };
    let (start, end) = (peak(0..tenth), peak(n.saturating_sub(tenth)..n));
    (start > 0.0 && end > 1e8 * start).then(|| {
        format!(
            "{name} grows from {start:.3e} to {end:.3e} over the record: the system that \
             produced it is unstable (or the record is corrupted), so no fit describes it"
        )
    })
}
