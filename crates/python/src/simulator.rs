//! A Python function as a simulator: the protocol's batch convention
//! (docs/protocol.md), `f(thetas [b, q], seeds [b], indices [b])`
//! returning `outputs [b, N, n_y]`, or `(inputs [b, N, n_u], outputs)`
//! for a model with inputs. Each experiment draws its randomness from its
//! own (seed, index) pair, so experiment i of a chart is the same bits
//! whatever batch it comes in, the thread count or the shard.

use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use twostage::models::{
    Block, Conditions, ExperimentRng, ExternalJob, IoData, ModelSpec, SimError, Simulator,
};

/// A Python callable simulating batches of experiments.
pub(crate) struct PythonSimulator {
    function: Py<PyAny>,
    spec: ModelSpec,
    batch: usize,
}

impl PythonSimulator {
    pub(crate) fn new(function: Py<PyAny>, spec: ModelSpec, batch: usize) -> Self {
        Self {
            function,
            spec,
            batch: batch.max(1),
        }
    }

    fn failure(&self, message: String) -> SimError {
        SimError::External {
            command: format!("the Python simulator of {}", self.spec.name()),
            message,
        }
    }

    /// Call the function on one block and copy its arrays into `outs`;
    /// an error here fails every experiment of the block.
    fn call(
        &self,
        py: Python<'_>,
        jobs: &[(u64, u64)],
        thetas: &[&[f64]],
        outs: &mut [IoData],
    ) -> Result<Vec<Result<(), SimError>>, SimError> {
        let (b, q) = (thetas.len(), self.spec.n_params());
        let flat: Vec<f64> = thetas.iter().flat_map(|t| t.iter().copied()).collect();
        let theta_array = PyArray1::from_vec(py, flat)
            .reshape([b, q])
            .map_err(|e| self.failure(format!("theta array: {e}")))?;
        let seeds = PyArray1::from_iter(py, jobs.iter().map(|(_, seed)| *seed));
        let indices = PyArray1::from_iter(py, jobs.iter().map(|(index, _)| *index));
        let answer = self
            .function
            .bind(py)
            .call1((theta_array, seeds, indices))
            .map_err(|e| self.failure(python_error(py, &e)))?;
        let (n, n_u, n_y) = (
            self.spec.n_samples(),
            self.spec.input_names().len(),
            self.spec.output_names().len(),
        );
        let (inputs, outputs) = if n_u == 0 && answer.cast::<PyTuple>().is_err() {
            (None, answer)
        } else {
            let pair =
                answer.cast::<PyTuple>().map_err(|_| {
                    self.failure(format!(
                    "it returned a {}, not the pair (inputs [b, N, {n_u}], outputs [b, N, {n_y}])",
                    answer.get_type().name().map_or("value".into(), |n| n.to_string())
                ))
                })?;
            if pair.len() != 2 {
                return Err(self.failure(format!(
                    "it returned a tuple of {}, not the pair (inputs, outputs)",
                    pair.len()
                )));
            }
            let inputs = pair.get_item(0).map_err(|e| self.failure(e.to_string()))?;
            let outputs = pair.get_item(1).map_err(|e| self.failure(e.to_string()))?;
            (Some(inputs), outputs)
        };
        let outputs = self.array("outputs", &outputs, [b, n, n_y])?;
        let inputs = match &inputs {
            Some(a) => Some(self.array("inputs", a, [b, n, n_u])?),
            None => None,
        };
        let mut results = Vec::with_capacity(b);
        for (k, out) in outs.iter_mut().enumerate() {
            out.resize(n, n_u, n_y);
            results.push(self.copy_record(k, jobs[k].0, inputs.as_ref(), &outputs, out));
        }
        Ok(results)
    }

    /// `value` as a float64 array of exactly `shape`, read-only.
    fn array<'py>(
        &self,
        what: &str,
        value: &Bound<'py, PyAny>,
        shape: [usize; 3],
    ) -> Result<numpy::PyReadonlyArrayDyn<'py, f64>, SimError> {
        let untyped = value.cast::<PyUntypedArray>().map_err(|_| {
            self.failure(format!(
                "its {what} are a {}, not a numpy array {shape:?}",
                value
                    .get_type()
                    .name()
                    .map_or("value".into(), |n| n.to_string())
            ))
        })?;
        let typed = value.cast::<PyArrayDyn<f64>>().map_err(|_| {
            self.failure(format!(
                "its {what} have dtype {}, not float64 (return np.float64 arrays)",
                untyped.dtype()
            ))
        })?;
        if untyped.shape() != shape {
            return Err(self.failure(format!(
                "its {what} have shape {:?}, expected {shape:?} (batch, samples, signals)",
                untyped.shape()
            )));
        }
        typed
            .try_readonly()
            .map_err(|e| self.failure(format!("its {what} cannot be read: {e}")))
    }

    /// Record `k` of the block into `out`; a non-finite sample fails it.
    fn copy_record(
        &self,
        k: usize,
        index: u64,
        inputs: Option<&numpy::PyReadonlyArrayDyn<'_, f64>>,
        outputs: &numpy::PyReadonlyArrayDyn<'_, f64>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        let outputs = outputs.as_array();
        for j in 0..out.n_outputs() {
            let column = out.output_mut(j);
            for (t, slot) in column.iter_mut().enumerate() {
                let v = outputs[[k, t, j]];
                if !v.is_finite() {
                    return Err(
                        self.failure(format!("experiment {index}: outputs[{k}, {t}, {j}] is {v}"))
                    );
                }
                *slot = v;
            }
        }
        if let Some(inputs) = inputs {
            let inputs = inputs.as_array();
            for j in 0..out.n_inputs() {
                let column = out.input_mut(j);
                for (t, slot) in column.iter_mut().enumerate() {
                    let v = inputs[[k, t, j]];
                    if !v.is_finite() {
                        return Err(self
                            .failure(format!("experiment {index}: inputs[{k}, {t}, {j}] is {v}")));
                    }
                    *slot = v;
                }
            }
        }
        Ok(())
    }
}

/// A Python exception as text: its type, message and traceback.
fn python_error(py: Python<'_>, error: &PyErr) -> String {
    let trace = error
        .traceback(py)
        .and_then(|t| t.format().ok())
        .unwrap_or_default();
    format!(
        "it raised {}{}",
        error,
        if trace.is_empty() {
            String::new()
        } else {
            format!("\n{trace}")
        }
    )
}

impl Simulator for PythonSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn batch_size(&self) -> usize {
        self.batch
    }

    /// One call of the function for the block (its capabilities are
    /// none, so the block is plain).
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        _: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<(), SimError>> {
        let jobs: Vec<(u64, u64)> = rngs.iter().map(ExternalJob::stream_of).collect();
        for theta in thetas {
            if theta.len() != self.spec.n_params() {
                let e = self.failure(format!(
                    "a parameter vector of {} values for {} parameters",
                    theta.len(),
                    self.spec.n_params()
                ));
                return thetas.iter().map(|_| Err(e.clone())).collect();
            }
        }
        Python::attach(|py| match self.call(py, &jobs, thetas, outs) {
            Ok(results) => results,
            Err(e) => thetas.iter().map(|_| Err(e.clone())).collect(),
        })
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        _: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        self.simulate_block(
            &[theta],
            std::slice::from_mut(rng),
            Block::default(),
            std::slice::from_mut(out),
        )
        .pop()
        .unwrap_or_else(|| Err(self.failure("no answer".into())))
    }
}

/// Progress reported to a Python callable `f(event, stage, count)`:
/// `("begin", "training", total)`, `("advance", "training", done)`,
/// `("end", "training", 0)`; the steps of other work (`"validating"`)
/// alike, by the step's name. Advances are gathered and passed on at most
/// ten times a second, so a chart of microsecond simulations does not wait
/// for the interpreter.
pub(crate) struct PythonProgress {
    callback: Py<PyAny>,
    pending: std::sync::atomic::AtomicUsize,
    last: std::sync::Mutex<std::time::Instant>,
    /// The step begun last (`begin_step`), which its advances report.
    step: std::sync::Mutex<&'static str>,
}

impl PythonProgress {
    pub(crate) fn new(callback: Py<PyAny>) -> Self {
        Self {
            callback,
            pending: std::sync::atomic::AtomicUsize::new(0),
            last: std::sync::Mutex::new(std::time::Instant::now()),
            step: std::sync::Mutex::new(""),
        }
    }

    /// Call the function; a failing progress callback must not stop
    /// training, so its exception is printed by Python and dropped.
    fn tell(&self, event: &str, stage: &str, count: usize) {
        Python::attach(|py| {
            if let Err(e) = self.callback.bind(py).call1((event, stage, count)) {
                e.print(py);
            }
        });
    }

    /// A message of the run, as `(event, message, 0)`.
    fn say(&self, event: &str, message: &str) {
        Python::attach(|py| {
            if let Err(e) = self.callback.bind(py).call1((event, message, 0)) {
                e.print(py);
            }
        });
    }

    fn flush(&self, stage: &str) {
        let done = self.pending.swap(0, std::sync::atomic::Ordering::Relaxed);
        if done > 0 {
            self.tell("advance", stage, done);
        }
    }

    /// `done` more, passed on when a tenth of a second has gone since the
    /// last report: whoever finds the clock free and the time gone reports.
    fn gather(&self, done: usize, stage: impl FnOnce() -> &'static str) {
        self.pending
            .fetch_add(done, std::sync::atomic::Ordering::Relaxed);
        if let Ok(mut last) = self.last.try_lock()
            && last.elapsed() >= std::time::Duration::from_millis(100)
        {
            *last = std::time::Instant::now();
            drop(last);
            self.flush(stage());
        }
    }

    fn current_step(&self) -> &'static str {
        self.step.lock().map_or("", |step| *step)
    }
}

impl twostage::Progress for PythonProgress {
    fn begin(&self, stage: twostage::Stage, total: usize) {
        self.pending.store(0, std::sync::atomic::Ordering::Relaxed);
        self.tell("begin", stage.label(), total);
    }

    fn advance(&self, stage: twostage::Stage, done: usize) {
        self.gather(done, || stage.label());
    }

    fn end(&self, stage: twostage::Stage) {
        self.flush(stage.label());
        self.tell("end", stage.label(), 0);
    }

    fn begin_step(&self, what: &'static str, total: usize, _unit: &'static str) {
        if let Ok(mut step) = self.step.lock() {
            *step = what;
        }
        self.pending.store(0, std::sync::atomic::Ordering::Relaxed);
        self.tell("begin", what, total);
    }

    fn advance_step(&self, done: usize) {
        self.gather(done, || self.current_step());
    }

    fn end_step(&self) {
        let what = self.current_step();
        self.flush(what);
        self.tell("end", what, 0);
    }

    fn note(&self, message: &str) {
        self.say("note", message);
    }

    fn status(&self, message: &str) {
        self.say("status", message);
    }
}
