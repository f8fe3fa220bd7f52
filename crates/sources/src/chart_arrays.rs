//! A chart given as arrays in memory (the Python package's numpy arrays),
//! read as a chart on disk is: the same checks, the same records in the
//! same order, so that an estimator trained on it is, bit for bit, the
//! one trained on the same arrays saved as a NumPy chart.

use ndarray::{Array2, Array3, ArrayView3};
use twostage_models::{IoData, ModelSpec};

use crate::error::{Error, Result};

/// A chart's arrays: `theta` `[m, q]`, `outputs` `[m, N, n_y]` and, for a
/// model with inputs, `inputs` `[m, N, n_u]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChartArrays {
    /// The parameters of each experiment.
    pub theta: Array2<f64>,
    /// Each experiment's inputs (`None` for a model without inputs).
    pub inputs: Option<Array3<f64>>,
    /// Each experiment's outputs.
    pub outputs: Array3<f64>,
}

/// How an array chart's problems are named: as the arrays the user gave.
fn refused(message: String) -> Error {
    Error::ChartFile {
        file: "chart".into(),
        line: None,
        message,
    }
}

impl ChartArrays {
    /// The arrays checked against `spec`: shapes (at least one
    /// experiment), every value finite.
    ///
    /// # Errors
    /// [`Error::ChartFile`] naming the array and, for a value, its index.
    pub(crate) fn check(&self, spec: &ModelSpec) -> Result<()> {
        let (q, n) = (spec.n_params(), spec.n_samples());
        let (n_u, n_y) = (spec.input_names().len(), spec.output_names().len());
        let m = self.theta.nrows();
        if self.theta.ncols() != q || m == 0 {
            return Err(refused(format!(
                "theta has shape {:?}: expected [m, {q}] (m experiments of the model's {q} \
                 parameters), m >= 1",
                self.theta.shape()
            )));
        }
        let shaped = |name: &str, array: ArrayView3<'_, f64>, width: usize| {
            if array.dim() != (m, n, width) {
                return Err(refused(format!(
                    "{name} has shape {:?}: expected [{m}, {n}, {width}] (experiments, samples, \
                     signals; theta has {m} experiments, the model {n} samples)",
                    array.shape()
                )));
            }
            Ok(())
        };
        shaped("outputs", self.outputs.view(), n_y)?;
        match (&self.inputs, n_u) {
            (Some(inputs), _) => shaped("inputs", inputs.view(), n_u)?,
            (None, 0) => {}
            (None, _) => {
                return Err(refused(format!(
                    "no inputs: the model has {n_u} input signals, give inputs [{m}, {n}, {n_u}]"
                )));
            }
        }
        if let Some(((i, j), v)) = self.theta.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(refused(format!(
                "theta[{i}, {j}] = {v} is not a finite number"
            )));
        }
        for (name, array) in [
            ("inputs", self.inputs.as_ref()),
            ("outputs", Some(&self.outputs)),
        ] {
            if let Some(((i, k, j), v)) =
                array.and_then(|a| a.indexed_iter().find(|(_, v)| !v.is_finite()))
            {
                return Err(refused(format!(
                    "{name}[{i}, {k}, {j}] = {v} is not a finite number"
                )));
            }
        }
        Ok(())
    }

    /// Experiments m.
    pub(crate) fn len(&self) -> usize {
        self.theta.nrows()
    }

    /// The parameters, row after row.
    pub(crate) fn thetas(&self) -> Vec<f64> {
        self.theta.iter().copied().collect()
    }

    /// Each record in row order, handed to `visit` with its row.
    pub(crate) fn for_each_record(
        &self,
        mut visit: impl FnMut(usize, &IoData) -> Result<()>,
    ) -> Result<()> {
        let (m, n, n_y) = self.outputs.dim();
        let n_u = self.inputs.as_ref().map_or(0, |u| u.dim().2);
        let mut record = IoData::zeros(n, n_u, n_y);
        for row in 0..m {
            for k in 0..n {
                if let Some(inputs) = &self.inputs {
                    for j in 0..n_u {
                        record.input_mut(j)[k] = inputs[[row, k, j]];
                    }
                }
                for j in 0..n_y {
                    record.output_mut(j)[k] = self.outputs[[row, k, j]];
                }
            }
            visit(row, &record)?;
        }
        Ok(())
    }
}
