//! The record itself as the features: for very short records (tens of
//! samples), where a least-squares fit would throw information away, the
//! whole record is the best compression there is (the paper's Section 4.2
//! allows any g; stage 2 then learns from every sample).

use crate::InvalidSetting;
use std::fmt;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::Compressor;
use crate::error::{CompressError, Result};
use crate::signals::{check_fixed_record, name};
use crate::workspace::Workspace;

/// The records' samples, each input then each output, sample by sample:
/// `N (n_u + n_y)` features for records of exactly `N` samples.
///
/// ```
/// use ndarray::array;
/// use twostage_compress::{Compressor, RawRecord};
/// let raw = RawRecord::new(3, 0, 1)?;
/// let no_input = ndarray::Array2::<f64>::zeros((3, 0));
/// let y = array![[1.0], [2.5], [4.0]];
/// assert_eq!(raw.compress(no_input.view(), y.view())?, [1.0, 2.5, 4.0]);
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RawRecord {
    n_samples: usize,
    n_inputs: usize,
    n_outputs: usize,
}

/// The most features a raw record may give: beyond this a least-squares
/// compressor serves better and stage 2 would not fit in memory.
pub const MAX_RAW_FEATURES: usize = 4096;

impl RawRecord {
    /// Records of `n_samples` samples, `n_inputs` inputs and `n_outputs`
    /// outputs.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for no sample, no output, or more
    /// than [`MAX_RAW_FEATURES`] features.
    pub fn new(n_samples: usize, n_inputs: usize, n_outputs: usize) -> Result<Self> {
        let features = n_samples.saturating_mul(n_inputs + n_outputs);
        if n_samples == 0 || n_outputs == 0 || features > MAX_RAW_FEATURES {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "raw record",
                value: format!("{n_samples} samples of {n_inputs} input(s), {n_outputs} output(s)"),
                reason: format!(
                    "at least one sample and one output, at most {MAX_RAW_FEATURES} values in \
                     all: for longer records use arx, ar or pca"
                ),
            }));
        }
        Ok(Self {
            n_samples,
            n_inputs,
            n_outputs,
        })
    }

    /// Samples per record.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }
}

impl fmt::Display for RawRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "raw record of {} samples", self.n_samples)
    }
}

impl Compressor for RawRecord {
    fn n_features(&self) -> usize {
        self.n_samples * (self.n_inputs + self.n_outputs)
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        _work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        check_fixed_record(
            inputs,
            outputs,
            self.n_inputs,
            self.n_outputs,
            self.n_samples,
            alpha.len(),
            self.n_features(),
            self,
        )?;
        let width = self.n_inputs + self.n_outputs;
        for (k, row) in alpha.chunks_exact_mut(width).enumerate() {
            let (u, y) = row.split_at_mut(self.n_inputs);
            for (j, v) in u.iter_mut().enumerate() {
                *v = inputs[[k, j]];
            }
            for (j, v) in y.iter_mut().enumerate() {
                *v = outputs[[k, j]];
            }
        }
        Ok(())
    }

    fn feature_names(&self) -> Vec<String> {
        (0..self.n_samples)
            .flat_map(|k| {
                (0..self.n_inputs)
                    .map(move |j| format!("{}[{k}]", name("u", j, self.n_inputs)))
                    .chain(
                        (0..self.n_outputs)
                            .map(move |j| format!("{}[{k}]", name("y", j, self.n_outputs))),
                    )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn samples_are_laid_out_input_then_output_per_sample() {
        let raw = RawRecord::new(2, 1, 2).unwrap();
        let (u, y) = (array![[1.0], [2.0]], array![[10.0, 20.0], [30.0, 40.0]]);
        let alpha = raw.compress(u.view(), y.view()).unwrap();
        assert_eq!(
            alpha.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            [1.0f64, 10.0, 20.0, 2.0, 30.0, 40.0].map(f64::to_bits)
        );
        assert_eq!(
            raw.feature_names(),
            ["u[0]", "y1[0]", "y2[0]", "u[1]", "y1[1]", "y2[1]"]
        );
        // Another length, a NaN, the wrong signals: refused, by name.
        let longer = array![[1.0], [2.0], [3.0]];
        assert!(
            raw.compress(
                longer.view(),
                array![[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]].view()
            )
            .is_err()
        );
        let e = raw
            .compress(u.view(), array![[1.0, f64::NAN], [1.0, 1.0]].view())
            .unwrap_err();
        assert!(e.to_string().contains("y2 has a non-finite value"), "{e}");
        assert!(RawRecord::new(0, 0, 1).is_err());
        assert!(RawRecord::new(5000, 0, 1).is_err());
    }
}
