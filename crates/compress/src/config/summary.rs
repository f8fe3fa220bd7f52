//! How hard a record's experiment drove the system, beside a stage-1
//! summary that does not say it: an ARX fit to a nonlinear system gives
//! coefficients that depend on the input's level and band as much as on
//! the parameters, so an estimator trained on a family of inputs cannot
//! tell a stiff tire driven gently from a soft one driven hard by the
//! coefficients alone. Appending each signal's level, size and mean
//! frequency (the numbers the input-family flag already reads) lets
//! stage 2 condition on the experiment (`SPEC+summary`).

use crate::InvalidSetting;
use std::fmt;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
use twostage_kernels::input_summary::{InputAccumulator, SUMMARY_NAMES};

use super::CompressorConfig;
use crate::error::{CompressError, Result};
use crate::signals::name;
use crate::{Compressor, Workspace};

/// The numbers appended per signal: [`SUMMARY_NAMES`].
const PER_SIGNAL: usize = SUMMARY_NAMES.len();

/// A compressor's features, then each input's and each output's mean,
/// RMS, peak and mean frequency (in cycles per sample, so the features
/// do not depend on a sample time the compressor is not told).
///
/// ```
/// use ndarray::{Array2, array};
/// use twostage_compress::{Compressor, CompressorConfig};
/// let c: CompressorConfig = "arx:1,1+summary".parse()?;
/// let c = c.for_shape(1, 1, 4)?;
/// assert_eq!(c.n_features(), 2 + 2 * 4);
/// // An input alternating between +1 and -1: mean 0, RMS 1, peak 1 and
/// // the highest frequency a sampled signal has (half a cycle a sample).
/// let u = array![[1.0], [-1.0], [1.0], [-1.0]];
/// let y = array![[0.0], [1.0], [-1.0], [1.0]];
/// let alpha = c.compress(u.view(), y.view())?;
/// let input = &alpha[2..6];
/// assert!(input[0].abs() < 1e-12 && (input[1] - 1.0).abs() < 1e-12);
/// assert!((input[2] - 1.0).abs() < 1e-12 && (input[3] - 0.5).abs() < 1e-12);
/// assert_eq!(c.spec().as_deref(), Some("arx:1,1+summary"));
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WithSummary {
    n_inputs: usize,
    n_outputs: usize,
    inner: Box<CompressorConfig>,
}

impl WithSummary {
    /// `inner`'s features, then the summary of each of `n_inputs` inputs
    /// and `n_outputs` outputs.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for an inner compressor that
    /// already appends the summary, or a record without signals.
    pub fn new(inner: CompressorConfig, n_inputs: usize, n_outputs: usize) -> Result<Self> {
        if n_inputs + n_outputs == 0 || matches!(inner, CompressorConfig::Summarized(_)) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "summary",
                value: format!("{inner} with {n_inputs} input(s), {n_outputs} output(s)"),
                reason: "one `+summary` after a compressor, for a model with signals".into(),
            }));
        }
        Ok(Self {
            n_inputs,
            n_outputs,
            inner: Box::new(inner),
        })
    }

    /// The compressor whose features come first.
    pub fn inner(&self) -> &CompressorConfig {
        &self.inner
    }

    /// The same signals' summary after `inner`.
    pub(crate) fn with_inner(&self, inner: CompressorConfig) -> Result<Self> {
        Self::new(inner, self.n_inputs, self.n_outputs)
    }

    /// The specification, `STAGE1+summary`, when the inner one has one.
    pub fn spec(&self) -> Option<String> {
        Some(format!("{}+summary", self.inner.spec()?))
    }

    fn appended(&self) -> usize {
        PER_SIGNAL * (self.n_inputs + self.n_outputs)
    }

    /// The summaries of `inputs` and `outputs` into `summary`, signal by
    /// signal, inputs first.
    fn summary_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        summary: &mut [f64],
    ) -> Result<()> {
        // The inner compressor has checked the samples; only the shape
        // the summary's slots follow is checked again.
        if inputs.ncols() != self.n_inputs || outputs.ncols() != self.n_outputs {
            return Err(CompressError::ShapeMismatch {
                inputs: self.n_inputs,
                outputs: self.n_outputs,
                got_inputs: inputs.ncols(),
                got_outputs: outputs.ncols(),
            });
        }
        if outputs.nrows() == 0 {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "record",
                value: "0 samples".into(),
                reason: "a record needs samples".into(),
            }));
        }
        let signals = inputs.columns().into_iter().chain(outputs.columns());
        for (column, numbers) in signals.zip(summary.chunks_exact_mut(PER_SIGNAL)) {
            let mut accumulator = InputAccumulator::new();
            column.iter().for_each(|&v| accumulator.push(v));
            numbers.copy_from_slice(&accumulator.summary(1.0));
        }
        Ok(())
    }

    fn split<'a>(&self, alpha: &'a mut [f64]) -> Result<(&'a mut [f64], &'a mut [f64])> {
        super::split_appended(alpha, self.inner.n_features(), self.appended())
    }
}

impl fmt::Display for WithSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} and each signal's mean, RMS, peak and mean frequency",
            self.inner
        )
    }
}

impl Compressor for WithSummary {
    fn n_features(&self) -> usize {
        self.inner.n_features() + self.appended()
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let (features, summary) = self.split(alpha)?;
        self.inner.compress_into(inputs, outputs, work, features)?;
        self.summary_into(inputs, outputs, summary)
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let (features, summary) = self.split(alpha)?;
        self.inner
            .compress_fast_into(inputs, outputs, work, features)?;
        self.summary_into(inputs, outputs, summary)
    }

    fn feature_names(&self) -> Vec<String> {
        let mut names = self.inner.feature_names();
        let signals = (0..self.n_inputs)
            .map(|j| name("u", j, self.n_inputs))
            .chain((0..self.n_outputs).map(|j| name("y", j, self.n_outputs)));
        for signal in signals {
            for number in SUMMARY_NAMES {
                names.push(format!("{signal}_{}", number.replace(' ', "_")));
            }
        }
        names
    }
}

#[cfg(test)]
mod tests {
    use ndarray::Array2;

    use super::*;

    /// The summary by a second computation: two passes over the samples
    /// (mean, then deviations) and the sinusoid's closed form for the
    /// frequency.
    fn by_hand(signal: &[f64]) -> [f64; 4] {
        let n = signal.len() as f64;
        let mean = signal.iter().sum::<f64>() / n;
        let variance = signal.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        let peak = signal.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max);
        let differences = signal
            .windows(2)
            .map(|w| (w[1] - w[0]).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        let frequency = (differences / (4.0 * variance)).sqrt().asin() / std::f64::consts::PI;
        [mean, variance.sqrt(), peak, frequency]
    }

    #[test]
    fn the_summary_follows_the_inner_features_signal_by_signal() {
        let n = 300;
        let u: Vec<f64> = (0..n).map(|k| (0.37 * k as f64).sin() + 0.2).collect();
        let y: Vec<f64> = (0..n)
            .map(|k| 3.0 * (0.11 * k as f64).cos() - 1.0)
            .collect();
        let inputs = Array2::from_shape_vec((n, 1), u.clone()).unwrap();
        let outputs = Array2::from_shape_vec((n, 1), y.clone()).unwrap();
        let inner: CompressorConfig = "arx:2,2".parse().unwrap();
        let inner = inner.for_shape(1, 1, n).unwrap();
        let c = WithSummary::new(inner.clone(), 1, 1).unwrap();
        let alpha = c.compress(inputs.view(), outputs.view()).unwrap();
        let arx = inner.compress(inputs.view(), outputs.view()).unwrap();
        assert_eq!(alpha[..4], arx[..]);
        for (got, want) in alpha[4..8].iter().zip(by_hand(&u)) {
            assert!((got - want).abs() < 1e-12, "input: {got} against {want}");
        }
        for (got, want) in alpha[8..].iter().zip(by_hand(&y)) {
            assert!((got - want).abs() < 1e-12, "output: {got} against {want}");
        }
        let mut fast = vec![0.0; c.n_features()];
        c.compress_fast_into(
            inputs.view(),
            outputs.view(),
            &mut Workspace::new(),
            &mut fast,
        )
        .unwrap();
        for (a, b) in fast.iter().zip(&alpha) {
            assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0));
        }
        assert_eq!(c.feature_names()[4], "u_mean");
        assert_eq!(c.feature_names()[11], "y_mean_frequency");
    }

    #[test]
    fn a_record_of_another_shape_or_twice_summarized_is_refused() {
        let inner: CompressorConfig = "arx:1,1".parse().unwrap();
        let once = WithSummary::new(inner.clone(), 1, 1).unwrap();
        assert!(WithSummary::new(CompressorConfig::Summarized(once.clone()), 1, 1).is_err());
        assert!(WithSummary::new(inner, 0, 0).is_err());
        let two_outputs = Array2::<f64>::zeros((10, 2));
        let one_input = Array2::<f64>::from_elem((10, 1), 1.0);
        let err = once
            .compress(one_input.view(), two_outputs.view())
            .unwrap_err();
        assert!(err.to_string().contains('2'), "{err}");
        // A buffer of another length than the inner features and the
        // summary's eight: refused, naming the count it needs.
        let one_output = Array2::<f64>::from_elem((10, 1), 1.0);
        let mut short = [0.0; 9];
        let err = once
            .compress_into(
                one_input.view(),
                one_output.view(),
                &mut Workspace::new(),
                &mut short,
            )
            .unwrap_err();
        assert!(err.to_string().contains("10 features"), "{err}");
    }
}
