//! The chart's records compressed by a candidate, and the rows it could
//! compress.

use ndarray::{Array2, Axis};
use rayon::prelude::*;
use twostage_compress::{Compressor, CompressorConfig, Workspace};
use twostage_models::IoData;
use twostage_train::Result;

/// Features of every record, in parallel (row i is record i). A record
/// the compressor cannot take (an ARX of a record whose input never
/// moves) gets a row of NaN, to be left out by [`readable_rows`], as long
/// as at most `allowed` of the records are such; beyond, the first one's
/// error.
pub(super) fn compress_all(
    compressor: &CompressorConfig,
    records: &[IoData],
    allowed: f64,
) -> Result<Array2<f64>> {
    let n = compressor.n_features();
    let mut features = vec![0.0; records.len() * n];
    let failures: Vec<(usize, twostage_compress::CompressError)> = features
        .par_chunks_mut(n.max(1))
        .zip(records.par_iter())
        .enumerate()
        .map_init(Workspace::new, |work, (i, (alpha, record))| {
            compressor
                .compress_into(record.inputs(), record.outputs(), work, alpha)
                .map_err(|e| {
                    alpha.fill(f64::NAN);
                    (i, e)
                })
                .err()
        })
        .flatten()
        .collect();
    if failures.len() as f64 > allowed * records.len() as f64
        && let Some((_, first)) = failures.into_iter().min_by_key(|(i, _)| *i)
    {
        return Err(first.into());
    }
    Ok(Array2::from_shape_vec((records.len(), n), features)
        .unwrap_or_else(|_| unreachable!("n features per record")))
}

/// The rows of `features` (and of `thetas`, row for row) that
/// [`compress_all`] could compress.
pub(super) fn readable_rows(
    features: ndarray::ArrayView2<'_, f64>,
    thetas: ndarray::ArrayView2<'_, f64>,
) -> (Array2<f64>, Array2<f64>) {
    let kept: Vec<usize> = features
        .rows()
        .into_iter()
        .enumerate()
        .filter(|(_, row)| row.iter().all(|v| !v.is_nan()))
        .map(|(i, _)| i)
        .collect();
    (
        features.select(Axis(0), &kept),
        thetas.select(Axis(0), &kept),
    )
}
