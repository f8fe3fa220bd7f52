//! Input/output records.

use ndarray::{ArrayView2, ShapeBuilder};

use crate::error::{Result, SimError};

/// One experiment's record: `n_samples` samples of `n_inputs` input signals
/// and `n_outputs` output signals, each signal stored as one contiguous
/// column (column-major), so MIMO systems use the same type as SISO ones.
///
/// A record is reused from simulation to simulation: [`IoData::resize`]
/// keeps the allocation.
///
/// ```
/// use twostage_models::IoData;
/// let data = IoData::siso(&[1.0, 2.0, 3.0], &[0.5, 0.25, 0.125])?;
/// assert_eq!(data.n_samples(), 3);
/// assert_eq!(data.input(0), &[1.0, 2.0, 3.0]);
/// assert_eq!(data.outputs().shape(), &[3, 1]);
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IoData {
    n_samples: usize,
    n_inputs: usize,
    n_outputs: usize,
    inputs: Vec<f64>,
    outputs: Vec<f64>,
}

impl IoData {
    /// A zero-filled record of the given shape.
    pub fn zeros(n_samples: usize, n_inputs: usize, n_outputs: usize) -> Self {
        let mut data = Self::default();
        data.resize(n_samples, n_inputs, n_outputs);
        data
    }

    /// A single-input single-output record from two equally long slices.
    ///
    /// # Errors
    /// [`SimError::InvalidData`] if the lengths differ or a sample is NaN or
    /// infinite (the message names the signal and the sample index).
    pub fn siso(u: &[f64], y: &[f64]) -> Result<Self> {
        if u.len() != y.len() {
            return Err(SimError::InvalidData(format!(
                "u has {} samples but y has {}: give one value of each per sample",
                u.len(),
                y.len()
            )));
        }
        let data = Self {
            n_samples: u.len(),
            n_inputs: 1,
            n_outputs: 1,
            inputs: u.to_vec(),
            outputs: y.to_vec(),
        };
        data.check_finite()?;
        Ok(data)
    }

    /// Samples `start..end` of every signal, as a record of their own (a
    /// window of a long record); `end` is cut to the record's length.
    ///
    /// ```
    /// use twostage_models::IoData;
    /// let data = IoData::siso(&[1.0, 2.0, 3.0, 4.0], &[0.1, 0.2, 0.3, 0.4])?;
    /// let last = data.window(2, 4);
    /// assert_eq!((last.input(0), last.output(0)), (&[3.0, 4.0][..], &[0.3, 0.4][..]));
    /// assert_eq!(data.window(3, 9).n_samples(), 1);
    /// # Ok::<(), twostage_models::SimError>(())
    /// ```
    pub fn window(&self, start: usize, end: usize) -> Self {
        let end = end.min(self.n_samples);
        let start = start.min(end);
        let mut part = Self::zeros(end - start, self.n_inputs, self.n_outputs);
        for j in 0..self.n_inputs {
            part.input_mut(j)
                .copy_from_slice(&self.input(j)[start..end]);
        }
        for j in 0..self.n_outputs {
            part.output_mut(j)
                .copy_from_slice(&self.output(j)[start..end]);
        }
        part
    }

    /// Reshape the record, keeping its allocation; the contents are zeroed.
    pub fn resize(&mut self, n_samples: usize, n_inputs: usize, n_outputs: usize) {
        self.n_samples = n_samples;
        self.n_inputs = n_inputs;
        self.n_outputs = n_outputs;
        self.inputs.clear();
        self.inputs.resize(n_samples * n_inputs, 0.0);
        self.outputs.clear();
        self.outputs.resize(n_samples * n_outputs, 0.0);
    }

    /// Number of samples N.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// Number of input signals.
    pub fn n_inputs(&self) -> usize {
        self.n_inputs
    }

    /// Number of output signals.
    pub fn n_outputs(&self) -> usize {
        self.n_outputs
    }

    /// Input signal `j` (panics if `j >= n_inputs`, a programming error).
    pub fn input(&self, j: usize) -> &[f64] {
        &self.inputs[j * self.n_samples..(j + 1) * self.n_samples]
    }

    /// Output signal `j` (panics if `j >= n_outputs`, a programming error).
    pub fn output(&self, j: usize) -> &[f64] {
        &self.outputs[j * self.n_samples..(j + 1) * self.n_samples]
    }

    /// Mutable input signal `j`.
    pub fn input_mut(&mut self, j: usize) -> &mut [f64] {
        &mut self.inputs[j * self.n_samples..(j + 1) * self.n_samples]
    }

    /// Mutable output signal `j`.
    pub fn output_mut(&mut self, j: usize) -> &mut [f64] {
        &mut self.outputs[j * self.n_samples..(j + 1) * self.n_samples]
    }

    /// Both signals of a SISO record at once, mutably: `(u, y)`.
    pub fn siso_mut(&mut self) -> (&mut [f64], &mut [f64]) {
        let n = self.n_samples;
        (&mut self.inputs[..n], &mut self.outputs[..n])
    }

    /// The inputs as an `N x n_inputs` view.
    pub fn inputs(&self) -> ArrayView2<'_, f64> {
        column_major(&self.inputs, self.n_samples, self.n_inputs)
    }

    /// The outputs as an `N x n_outputs` view.
    pub fn outputs(&self) -> ArrayView2<'_, f64> {
        column_major(&self.outputs, self.n_samples, self.n_outputs)
    }

    /// Check that every sample is finite.
    ///
    /// # Errors
    /// [`SimError::InvalidData`] naming the first non-finite sample.
    pub fn check_finite(&self) -> Result<()> {
        let signals = (0..self.n_inputs)
            .map(|j| ("input", j, self.input(j)))
            .chain((0..self.n_outputs).map(|j| ("output", j, self.output(j))));
        for (kind, j, signal) in signals {
            if let Some(k) = signal.iter().position(|v| !v.is_finite()) {
                return Err(SimError::InvalidData(format!(
                    "{kind} {j} has a non-finite value ({}) at sample {k}: \
                     remove or repair that sample",
                    signal[k]
                )));
            }
        }
        Ok(())
    }
}

fn column_major(values: &[f64], rows: usize, cols: usize) -> ArrayView2<'_, f64> {
    // The length always matches because `resize` is the only way to set it.
    ArrayView2::from_shape((rows, cols).f(), values)
        .unwrap_or_else(|_| unreachable!("IoData keeps rows * cols values"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_contiguous_and_views_agree() {
        let mut data = IoData::zeros(4, 2, 1);
        data.input_mut(1).copy_from_slice(&[1.0, 2.0, 3.0, 4.0]);
        data.output_mut(0)[2] = 7.0;
        let view = data.inputs();
        assert_eq!(view.shape(), &[4, 2]);
        assert_eq!(view[[3, 1]].to_bits(), 4.0f64.to_bits());
        assert_eq!(view[[3, 0]].to_bits(), 0.0f64.to_bits());
        assert_eq!(data.outputs()[[2, 0]].to_bits(), 7.0f64.to_bits());
    }

    #[test]
    fn siso_rejects_mismatched_lengths_and_non_finite_samples() {
        let err = IoData::siso(&[1.0, 2.0], &[1.0]).unwrap_err();
        assert!(err.to_string().contains("u has 2 samples but y has 1"));
        let err = IoData::siso(&[1.0, 2.0], &[1.0, f64::NAN]).unwrap_err();
        assert!(err.to_string().contains("output 0"), "{err}");
        assert!(err.to_string().contains("sample 1"), "{err}");
    }

    #[test]
    fn resize_zeroes_and_reshapes() {
        let mut data = IoData::siso(&[1.0; 3], &[2.0; 3]).unwrap();
        data.resize(5, 1, 2);
        assert_eq!(data.n_samples(), 5);
        assert!(data.output(1).iter().all(|v| v.to_bits() == 0));
    }
}

/// The signals and sampling a record must have: one shape for a model's
/// records, an estimator's and a shard's.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RecordShape {
    /// Samples per record the estimator was trained on.
    pub n_samples: usize,
    /// Input signals.
    pub n_inputs: usize,
    /// Output signals.
    pub n_outputs: usize,
    /// Sampling time.
    pub sample_time: f64,
}
