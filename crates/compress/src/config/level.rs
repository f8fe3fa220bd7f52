//! The level of a record beside a stage-1 summary that discards it: an
//! ARX regression fits deviations from the record's dynamics, so two
//! records at different levels (a tank starting fuller, a sensor offset)
//! give the same coefficients. Appending each output's first sample and
//! mean keeps what an initial state or an offset leaves in the record
//! (`SPEC+level`).

use crate::InvalidSetting;
use std::fmt;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use super::CompressorConfig;
use crate::error::{CompressError, Result};
use crate::signals::name;
use crate::{Compressor, Workspace};

/// A compressor's features, then each output's first sample and mean.
///
/// ```
/// use ndarray::array;
/// use twostage_compress::{Compressor, CompressorConfig};
/// let c: CompressorConfig = "ar:1+level".parse()?;
/// let c = c.for_shape(0, 1, 4)?;
/// // y_k = 0.5 y_{k-1} around no offset, starting at 8.
/// let y = array![[8.0], [4.0], [2.0], [1.0]];
/// let no_input = ndarray::Array2::<f64>::zeros((4, 0));
/// let alpha = c.compress(no_input.view(), y.view())?;
/// assert!((alpha[0] - 0.5).abs() < 1e-12);
/// assert_eq!(alpha[1..], [8.0, 3.75]);
/// assert_eq!(c.spec().as_deref(), Some("ar:1+level"));
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WithLevel {
    n_outputs: usize,
    inner: Box<CompressorConfig>,
}

impl WithLevel {
    /// `inner`'s features, then the level of each of `n_outputs` outputs.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for an inner compressor that
    /// already adds the level, or no output.
    pub fn new(inner: CompressorConfig, n_outputs: usize) -> Result<Self> {
        if n_outputs == 0 || matches!(inner, CompressorConfig::Leveled(_)) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "level",
                value: format!("{inner} with {n_outputs} output(s)"),
                reason: "one `+level` after a compressor, for a model with outputs".into(),
            }));
        }
        Ok(Self {
            n_outputs,
            inner: Box::new(inner),
        })
    }

    /// The compressor whose features come first.
    pub fn inner(&self) -> &CompressorConfig {
        &self.inner
    }

    /// Outputs whose level is appended.
    pub(crate) fn n_outputs(&self) -> usize {
        self.n_outputs
    }

    /// The same for `n_outputs` outputs, with `inner` in place.
    pub(crate) fn shaped(&self, n_outputs: usize, inner: CompressorConfig) -> Result<Self> {
        Self::new(inner, n_outputs)
    }

    /// The specification, `STAGE1+level`, when the inner one has one.
    pub fn spec(&self) -> Option<String> {
        Some(format!("{}+level", self.inner.spec()?))
    }

    /// The level features of `outputs` into `level` (first sample, mean).
    fn level_into(&self, outputs: ArrayView2<'_, f64>, level: &mut [f64]) -> Result<()> {
        if outputs.ncols() != self.n_outputs {
            return Err(CompressError::ShapeMismatch {
                inputs: 0,
                outputs: self.n_outputs,
                got_inputs: 0,
                got_outputs: outputs.ncols(),
            });
        }
        for (j, pair) in level.chunks_exact_mut(2).enumerate() {
            let column = outputs.column(j);
            let first = column
                .first()
                .copied()
                .ok_or(CompressError::InvalidSetting(InvalidSetting {
                    name: "record",
                    value: "0 samples".into(),
                    reason: "a record needs samples".into(),
                }))?;
            let mean = column.sum() / column.len() as f64;
            if !(first.is_finite() && mean.is_finite()) {
                return Err(CompressError::NonFinite {
                    signal: name("y", j, self.n_outputs),
                    index: 0,
                    value: if first.is_finite() { mean } else { first },
                });
            }
            pair.copy_from_slice(&[first, mean]);
        }
        Ok(())
    }

    fn split<'a>(&self, alpha: &'a mut [f64]) -> Result<(&'a mut [f64], &'a mut [f64])> {
        super::split_appended(alpha, self.inner.n_features(), 2 * self.n_outputs)
    }
}

impl fmt::Display for WithLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} and each output's first sample and mean", self.inner)
    }
}

impl Compressor for WithLevel {
    fn n_features(&self) -> usize {
        self.inner.n_features() + 2 * self.n_outputs
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let (features, level) = self.split(alpha)?;
        self.inner.compress_into(inputs, outputs, work, features)?;
        self.level_into(outputs, level)
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let (features, level) = self.split(alpha)?;
        self.inner
            .compress_fast_into(inputs, outputs, work, features)?;
        self.level_into(outputs, level)
    }

    fn feature_names(&self) -> Vec<String> {
        let mut names = self.inner.feature_names();
        for j in 0..self.n_outputs {
            let y = name("y", j, self.n_outputs);
            names.push(format!("{y}_first"));
            names.push(format!("{y}_mean"));
        }
        names
    }
}
