//! The native module of the `twostage` Python package
//! (`twostage._twostage`): estimator files, estimates from numpy arrays
//! with the GIL released and the records in parallel, and training from a
//! built-in model or a model file. The Python layer
//! (`python/twostage/__init__.py`) turns the JSON reports into plain data.
//!
//! Arrays come in as float64 only, never cast: a record in float32 or int
//! would estimate something other than what the CLI estimates from the same
//! numbers. Every rejection is a `ValueError` naming the argument and, for
//! a bad value, its index.
#![deny(missing_docs)]

use std::path::PathBuf;

use ndarray::{ArrayView2, ArrayView3, Axis};
use numpy::{IntoPyArray, PyArrayDyn};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rayon::prelude::*;
use twostage::EstimateWorkspace;

use arrays::{as_batch, non_finite, records, rows, shape_error};

mod arrays;
mod joint;
mod requests;
mod simulator;
mod through_model;
mod training;

/// A twostage error as the Python exception a caller would expect: a file
/// that cannot be read is an `OSError`, everything else a `ValueError`.
fn to_python(error: impl Into<twostage::Error>) -> PyErr {
    match error.into() {
        error @ (twostage::Error::Estimator(twostage::estimator::Error::Io { .. })
        | twostage::Error::Source(twostage::sources::Error::Io { .. })) => {
            PyOSError::new_err(error.to_string())
        }
        other => PyValueError::new_err(other.to_string()),
    }
}

/// A trained estimator: the same files as the command line's.
#[pyclass(name = "Estimator", module = "twostage", frozen)]
struct PyEstimator {
    inner: twostage::Estimator,
}

#[pymethods]
impl PyEstimator {
    /// Read an estimator file (written by `twostage train`, `save`, or any
    /// earlier format version).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        twostage::Estimator::load(&path)
            .map(|inner| Self { inner })
            .map_err(to_python)
    }

    /// An estimator from the bytes of a file.
    #[staticmethod]
    fn from_bytes(data: &[u8]) -> PyResult<Self> {
        twostage::Estimator::from_bytes(data)
            .map(|inner| Self { inner })
            .map_err(to_python)
    }

    /// Write the estimator file.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.inner.save(&path).map_err(to_python)
    }

    /// The file's bytes.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = self.inner.to_bytes().map_err(to_python)?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// The estimator as a blob for the microcontroller runtime and its C
    /// API (what `twostage export --to runtime` writes).
    fn to_runtime<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let blob = self.inner.to_runtime().map_err(to_python)?;
        Ok(PyBytes::new(py, &blob))
    }

    /// Parameter names, in the order of theta.
    #[getter]
    fn parameters(&self) -> Vec<String> {
        self.inner.param_names().to_vec()
    }

    /// The parameters held at values while it trained, name to value.
    #[getter]
    fn fixed(&self) -> Vec<(String, f64)> {
        self.inner
            .fixed()
            .values()
            .iter()
            .map(|v| (v.name.clone(), v.value))
            .collect()
    }

    /// The prior box's lower corner.
    #[getter]
    fn lower(&self) -> Vec<f64> {
        self.inner.lower().to_vec()
    }

    /// The prior box's upper corner.
    #[getter]
    fn upper(&self) -> Vec<f64> {
        self.inner.upper().to_vec()
    }

    /// (samples per record, inputs, outputs) the estimator was trained on.
    #[getter]
    fn record_shape(&self) -> (usize, usize, usize) {
        let shape = self.inner.record_shape();
        (shape.n_samples, shape.n_inputs, shape.n_outputs)
    }

    /// The `[[preset]]` block of a model file that trains this structure
    /// again without searching, named `name`; None when a stage has no
    /// command-line form.
    #[pyo3(signature = (name = "searched"))]
    fn preset_block(&self, name: &str) -> Option<String> {
        self.inner.preset_block(name)
    }

    /// The model's name.
    #[getter]
    fn model(&self) -> String {
        self.inner.training().model.clone()
    }

    /// The whole estimator as JSON (the CLI's `inspect --json` reads the
    /// same fields).
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(to_python)
    }

    /// The validation report as JSON, or None when not validated.
    fn validation_json(&self) -> PyResult<Option<String>> {
        self.inner
            .validation()
            .map(|report| {
                serde_json::to_string(report)
                    .map_err(|e| PyValueError::new_err(format!("validation report: {e}")))
            })
            .transpose()
    }

    /// Estimates of one record (`u` `[N, n_u]`, `y` `[N, n_y]`: theta `[q]`) or
    /// of a batch (`u` [b, N, n_u], `y` [b, N, n_y]: theta [b, q]), the
    /// records in parallel without the GIL. `u` is None for a model
    /// without input.
    #[pyo3(signature = (u, y))]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let q = self.inner.param_names().len();
        let estimator = &self.inner;
        let (theta, single) = self.each_record(py, u, y, q, |_, u, y, work, out| {
            Ok(estimator.estimate_into(u, y, work, out)?)
        })?;
        Ok(rows(py, theta, q, single))
    }

    /// `n` draws from the estimator's posterior given one record (`u`
    /// `[N, n_u]`, `y` `[N, n_y]`: draws `[n, q]`) or each record of a
    /// batch (draws `[b, n, q]`), the records in parallel without the GIL;
    /// record k's draws come from the stream of (`seed`, k), as `twostage
    /// estimate --samples n --seed SEED` draws for the k-th record of a
    /// file, so both give the same numbers.
    #[pyo3(signature = (u, y, n, *, seed=0))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
        n: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.draws_refused(n)?;
        let q = self.inner.param_names().len();
        let estimator = &self.inner;
        let (draws, single) = self.each_record(py, u, y, n * q, |k, u, y, work, out| {
            let mut rng = posterior_stream(seed, k);
            Ok(estimator.sample_into(u, y, work, &mut rng, out)?)
        })?;
        let shape = if single {
            vec![n, q]
        } else {
            vec![draws.len() / (n * q).max(1), n, q]
        };
        ndarray::ArrayD::from_shape_vec(shape, draws)
            .map(|a| a.into_pyarray(py).into_any())
            .map_err(|e| PyValueError::new_err(format!("draws: {e}")))
    }

    /// Whether the values `at` (`[q]`) are ones the record allows: for
    /// one record (a float) or each record of a batch (`[b]`), the
    /// smallest level of its posterior's region of highest density that
    /// holds them, by the `n` draws `sample` gives with the same `seed`
    /// (the share of them the posterior finds more probable; at most 0.9
    /// where `at` lies in the joint 90% region), as `twostage estimate
    /// --samples n --seed SEED --at` writes it in `region_level`.
    #[pyo3(signature = (u, y, at, n, *, seed=0))]
    fn region_level<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
        at: Vec<f64>,
        n: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.draws_refused(n)?;
        let q = self.inner.param_names().len();
        if at.len() != q {
            return Err(PyValueError::new_err(format!(
                "at: {} values, the estimator has {q} parameters ({})",
                at.len(),
                self.inner.param_names().join(", ")
            )));
        }
        let estimator = &self.inner;
        let (levels, single) = self.each_record(py, u, y, 1, |k, u, y, work, out| {
            let mut rng = posterior_stream(seed, k);
            let mut draws = vec![0.0; n * q];
            out[0] = estimator.sample_testing((u, y), work, &mut rng, &mut draws, &at)?;
            Ok(())
        })?;
        Ok(if single {
            levels[0].into_pyobject(py)?.into_any()
        } else {
            levels.into_pyarray(py).into_any()
        })
    }

    /// The last sample (from 1) of each window of `window` samples, one
    /// every `every`, of a record of `samples` samples: the estimate
    /// request's windows, refused in its words.
    #[pyo3(signature = (samples, window, every))]
    fn window_ends(&self, samples: usize, window: usize, every: usize) -> PyResult<Vec<usize>> {
        let windows = twostage::Windows {
            length: window,
            every,
        };
        if let Some(refused) = windows.refused() {
            return Err(PyValueError::new_err(format!("the windows: {refused}")));
        }
        windows
            .ends(samples, "the record")
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Estimates with their intervals and the out-of-distribution flag, for
    /// one record or a batch: `(theta, half_widths, feature_distance,
    /// distance_threshold, untransformed, input_outside)`, the half-widths
    /// those of the adaptive intervals where calibrated, else of the
    /// conformal ones (None when neither is), the distance None without a
    /// feature envelope, `input_outside` the count of ways the record's
    /// input lies outside the estimator's input family (None without one).
    #[pyo3(signature = (u, y))]
    #[allow(clippy::type_complexity)]
    fn assess<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
    ) -> PyResult<(
        Bound<'py, PyAny>,
        Option<Bound<'py, PyAny>>,
        Option<Bound<'py, PyAny>>,
        Option<f64>,
        Option<Bound<'py, PyAny>>,
        Option<Bound<'py, PyAny>>,
    )> {
        let q = self.inner.param_names().len();
        let estimator = &self.inner;
        // Per record: theta, half-widths (NaN when none), distance (NaN
        // when none), samples outside the output transform, ways its
        // input lies outside the family.
        let width = 2 * q + 3;
        let (values, single) = self.each_record(py, u, y, width, |_, u, y, work, out| {
            let assessment = estimator.assess_with(u, y, work)?;
            let (theta, rest) = out.split_at_mut(q);
            theta.copy_from_slice(&assessment.theta);
            let (widths, rest) = rest.split_at_mut(q);
            match assessment.interval_half_widths() {
                Some(w) => widths.copy_from_slice(w),
                None => widths.fill(f64::NAN),
            }
            rest[0] = assessment.feature_distance.unwrap_or(f64::NAN);
            rest[1] = assessment.floored_samples.len() as f64;
            rest[2] = assessment.input_deviations.len() as f64
                + f64::from(u8::from(assessment.input_shape_outside()));
            Ok(())
        })?;
        let column = |from: usize, to: usize| -> Vec<f64> {
            values
                .chunks_exact(width)
                .flat_map(|row| row[from..to].iter().copied())
                .collect()
        };
        // One number per record: a float, or an array for a batch.
        let per_record = |values: Vec<f64>| -> Bound<'py, PyAny> {
            if single {
                values[0]
                    .into_pyobject(py)
                    .map(|v| v.into_any())
                    .unwrap_or_else(|e| match e {})
            } else {
                ndarray::Array1::from_vec(values)
                    .into_pyarray(py)
                    .into_any()
            }
        };
        let theta = rows(py, column(0, q), q, single);
        let widths = (self.inner.intervals().is_some()
            || self.inner.adaptive_intervals().is_some())
        .then(|| rows(py, column(q, 2 * q), q, single));
        let threshold = self
            .inner
            .envelope()
            .map(twostage::FeatureEnvelope::threshold);
        let distance = threshold.map(|_| per_record(column(2 * q, 2 * q + 1)));
        let floored = self
            .inner
            .transforms_outputs()
            .then(|| per_record(column(2 * q + 1, 2 * q + 2)));
        let input_outside = self
            .inner
            .input_family()
            .map(|_| per_record(column(2 * q + 2, width)));
        Ok((theta, widths, distance, threshold, floored, input_outside))
    }

    /// How each record's input lies outside the estimator's input family,
    /// in words: a list of sentences per record (one record: one list);
    /// empty lists inside the family, and for an estimator without one.
    #[pyo3(signature = (u, y))]
    fn input_deviations<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
    ) -> PyResult<Vec<Vec<String>>> {
        let estimator = &self.inner;
        let said = std::sync::Mutex::new(Vec::new());
        let (indices, _) = self.each_record(py, u, y, 1, |_, u, _, _, out| {
            let mut sentences: Vec<String> = estimator
                .input_deviations(u)
                .iter()
                .map(ToString::to_string)
                .collect();
            let threshold = estimator
                .input_shapes()
                .map(twostage::models::InputShapes::threshold);
            if let (Some(d), Some(t)) = (estimator.input_shape_distance(u), threshold)
                && (d > t || d.is_nan())
            {
                sentences.push(twostage::models::input_shape_words(d, t));
            }
            let mut all = said
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            out[0] = all.len() as f64;
            all.push(sentences);
            Ok(())
        })?;
        // Records may be judged in any order: put each list back in its
        // record's place.
        let mut all = said
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        Ok(indices
            .iter()
            .map(|&slot| std::mem::take(&mut all[slot as usize]))
            .collect())
    }

    /// Check one record's estimate against the record (`twostage estimate
    /// --check`): `theta`, or the estimator's own estimate when None,
    /// simulated without noise on the record's input and ranked among
    /// `sims` of the model's own records of `seed`, scored from sample
    /// `score_from` on, and judged against the best fit searched from it
    /// (and its interval's corners, for the estimator's own estimate) and
    /// from `prior_starts` starts over the prior (default two per
    /// parameter and two more). The model: the
    /// estimator's built-in one, or its model file (`model_file` or
    /// `model_toml`).
    #[pyo3(signature = (u, y, theta=None, *, model_file=None, model_toml=None, sims=None, seed=0, score_from=0, score_to=None, prior_starts=None))]
    #[allow(clippy::too_many_arguments)]
    fn check<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
        theta: Option<Vec<f64>>,
        model_file: Option<PathBuf>,
        model_toml: Option<&str>,
        sims: Option<usize>,
        seed: u64,
        score_from: usize,
        score_to: Option<usize>,
        prior_starts: Option<usize>,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        requests::check(
            &self.inner,
            py,
            u,
            y,
            theta,
            model_file,
            model_toml,
            sims,
            seed,
            score_from,
            score_to,
            prior_starts,
        )
    }

    /// The estimator validated on fresh simulations of its model, as
    /// `twostage validate` does (the same plan gives the same report, bit
    /// for bit): `(report_json, truth [r, q], estimates [r, q], target)`,
    /// `target` None without `target_rmse`, else `(met, ratio)`. The
    /// records run without the GIL, reported to `progress` as `train`'s
    /// are. The model: the estimator's built-in one, or its model file
    /// (`model_file` or `model_toml`).
    #[pyo3(signature = (*, model_file=None, model_toml=None, sims=None, gamma=None, delta=None, seed=None, target_rmse=None, max_sims=None, progress=None))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn validate<'py>(
        &self,
        py: Python<'py>,
        model_file: Option<PathBuf>,
        model_toml: Option<&str>,
        sims: Option<usize>,
        gamma: Option<f64>,
        delta: Option<f64>,
        seed: Option<u64>,
        target_rmse: Option<f64>,
        max_sims: Option<usize>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<(
        String,
        Bound<'py, PyArrayDyn<f64>>,
        Bound<'py, PyArrayDyn<f64>>,
        Option<(bool, f64)>,
    )> {
        requests::validate(
            &self.inner,
            py,
            model_file,
            model_toml,
            sims,
            gamma,
            delta,
            seed,
            target_rmse,
            max_sims,
            progress,
        )
    }

    /// The records of the CSV file at `path`, read as `twostage estimate`
    /// reads them: `(records, failed)`, each record `(experiment, u, y)`,
    /// each failure `(experiment, why)` (file, row, column).
    #[allow(clippy::type_complexity)]
    fn read_records<'py>(
        &self,
        py: Python<'py>,
        path: PathBuf,
    ) -> PyResult<(
        Vec<(String, Bound<'py, PyAny>, Bound<'py, PyAny>)>,
        Vec<(String, String)>,
    )> {
        requests::read_records(&self.inner, py, path)
    }

    /// Every record of `records` (pairs `(u, y)`, named `experiments` or
    /// by index) as `twostage estimate --estimator` estimates a file of
    /// them with the same flags (`check`, `refine` "all" or "auto",
    /// `refine_below_fit`, `joint`, `window`/`every`, `correlation`,
    /// `sims` as `--check-sims`, `score_from`, `prior_starts`, `seed`):
    /// `(rows_json, failed, auto)`, the rows as its `--format json`
    /// writes them, the records that could not be estimated (experiment,
    /// why), and with `refine="auto"` `(explained, checked, [(experiment,
    /// reason)])`. `fix={name: value}` holds parameters there, as
    /// `--fix`: the rows are of the others.
    #[pyo3(signature = (records, *, experiments=None, check=false, refine=None, refine_below_fit=None, joint=false, window=None, every=None, correlation=false, model_file=None, model_toml=None, sims=None, score_from=0, score_to=None, prior_starts=None, seed=0, progress=None, fix=None))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn estimate_records<'py>(
        &self,
        py: Python<'py>,
        records: Vec<(Option<Bound<'py, PyAny>>, Bound<'py, PyAny>)>,
        experiments: Option<Vec<String>>,
        check: bool,
        refine: Option<&str>,
        refine_below_fit: Option<f64>,
        joint: bool,
        window: Option<usize>,
        every: Option<usize>,
        correlation: bool,
        model_file: Option<PathBuf>,
        model_toml: Option<&str>,
        sims: Option<usize>,
        score_from: usize,
        score_to: Option<usize>,
        prior_starts: Option<usize>,
        seed: u64,
        progress: Option<Py<PyAny>>,
        fix: Option<Bound<'py, pyo3::types::PyDict>>,
    ) -> PyResult<(
        String,
        Vec<(String, String)>,
        Option<(usize, usize, Vec<(String, String)>)>,
    )> {
        let fix = training::fixed_values(fix)?;
        requests::estimate_records(
            &self.inner,
            py,
            records,
            experiments,
            check,
            refine,
            refine_below_fit,
            joint,
            window,
            every,
            correlation,
            model_file,
            model_toml,
            sims,
            score_from,
            score_to,
            prior_starts,
            seed,
            progress,
            fix,
        )
    }

    /// One estimate of the plant behind all `records` (pairs `(u, y)`, any
    /// lengths), as `twostage estimate --joint`: their two-stage
    /// estimates pooled, then one output-error fit of every record on its
    /// own input, searched from `prior_starts` starts over the prior of
    /// `seed` besides them; `fix={name: value}` holds parameters there,
    /// as `--fix`. See `joint::joint_dict` for the keys.
    #[pyo3(signature = (records, *, model_file=None, model_toml=None, prior_starts=None, seed=0, fix=None))]
    #[allow(clippy::too_many_arguments)]
    fn joint<'py>(
        &self,
        py: Python<'py>,
        records: Vec<(Option<Bound<'py, PyAny>>, Bound<'py, PyAny>)>,
        model_file: Option<PathBuf>,
        model_toml: Option<&str>,
        prior_starts: Option<usize>,
        seed: u64,
        fix: Option<Bound<'py, pyo3::types::PyDict>>,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let fix = training::fixed_values(fix)?;
        requests::joint(
            &self.inner,
            py,
            records,
            model_file,
            model_toml,
            prior_starts,
            seed,
            fix,
        )
    }

    /// Refine one record's estimate through the model (`twostage estimate
    /// --refine`): a dict of the refined `theta`, its own interval
    /// `half_widths` (None, with `interval_error` saying why, where the
    /// record does not determine a parameter), the `correlation` matrix,
    /// and `stop`, why the output-error descent stopped (None for a
    /// built-in model's posterior mean). Raises ValueError when the model
    /// cannot be evaluated near the estimate: the two-stage estimate
    /// stands.
    #[pyo3(signature = (u, y, *, model_file=None, model_toml=None))]
    fn refine<'py>(
        &self,
        py: Python<'py>,
        u: Option<&Bound<'py, PyAny>>,
        y: &Bound<'py, PyAny>,
        model_file: Option<PathBuf>,
        model_toml: Option<&str>,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        requests::refine(&self.inner, py, u, y, model_file, model_toml)
    }
}

/// Why a record was not estimated.
enum Failure {
    /// A sample that is not a finite number, named by its index.
    Value(String),
    /// What the estimator said.
    Estimate(twostage::Error),
}

impl PyEstimator {
    /// `n` draws a record refused as every door refuses them, said as
    /// the argument `n`.
    fn draws_refused(&self, n: usize) -> PyResult<()> {
        match twostage::draws_refused(n, Some(&self.inner), false) {
            Some(refused) => Err(PyValueError::new_err(format!("n: {refused}"))),
            None => Ok(()),
        }
    }

    /// Check `u` and `y`, then run `each` on every record in parallel
    /// without the GIL, each writing `width` numbers; the first failure
    /// (by record index) becomes a `ValueError` naming the record.
    fn each_record(
        &self,
        py: Python<'_>,
        u: Option<&Bound<'_, PyAny>>,
        y: &Bound<'_, PyAny>,
        width: usize,
        each: impl Fn(
            usize,
            ArrayView2<'_, f64>,
            ArrayView2<'_, f64>,
            &mut EstimateWorkspace,
            &mut [f64],
        ) -> twostage::Result<()>
        + Sync,
    ) -> PyResult<(Vec<f64>, bool)> {
        let shape = self.inner.record_shape();
        let (y_array, single) = records("y", Some(y), shape.n_outputs, None)?;
        let Some(y_array) = y_array else {
            return Err(PyValueError::new_err(
                "y is None: pass the outputs [N, n_y]",
            ));
        };
        let y_view = as_batch(&y_array)?;
        let (b, n) = (y_view.shape()[0], y_view.shape()[1]);
        if let Some(refusal) = self.inner.length_refusal(n) {
            return Err(PyValueError::new_err(refusal));
        }
        let (u_array, u_single) = records("u", u, shape.n_inputs, (!single).then_some(b))?;
        if u_array.is_some() && u_single != single {
            return Err(PyValueError::new_err(
                "u is a batch and y one record: give both as one record or both as batches",
            ));
        }
        let u_view = match &u_array {
            Some(u_array) => as_batch(u_array)?,
            None => ArrayView3::from_shape((b, n, 0), &[]).map_err(shape_error)?,
        };
        let (values, failure) = py.detach(|| {
            let mut values = vec![0.0; b * width];
            // The lowest failing record's error, whatever the scheduling.
            let failure = values
                .par_chunks_mut(width.max(1))
                .enumerate()
                .map_init(EstimateWorkspace::new, |work, (k, out)| {
                    let (u, y) = (u_view.index_axis(Axis(0), k), y_view.index_axis(Axis(0), k));
                    // Checked here, record by record in the workers, while
                    // the record is in cache: a pass over a whole batch
                    // first would cost most of a batch's estimates.
                    if let Some(bad) =
                        non_finite("u", u, k, single).or_else(|| non_finite("y", y, k, single))
                    {
                        return Some((k, Failure::Value(bad)));
                    }
                    each(k, u, y, work, out)
                        .err()
                        .map(|e| (k, Failure::Estimate(e)))
                })
                .flatten()
                .min_by_key(|(k, _)| *k);
            (values, failure)
        });
        match failure {
            None => Ok((values, single)),
            Some((_, Failure::Value(message))) => Err(PyValueError::new_err(message)),
            Some((_, Failure::Estimate(e))) if single => Err(PyValueError::new_err(e.to_string())),
            Some((k, Failure::Estimate(e))) => {
                Err(PyValueError::new_err(format!("record {k}: {e}")))
            }
        }
    }
}

/// The native module.
#[pymodule]
fn _twostage(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add_class::<PyEstimator>()?;
    module.add_function(wrap_pyfunction!(training::train, module)?)?;
    module.add_function(wrap_pyfunction!(through_model::check_values, module)?)?;
    module.add_function(wrap_pyfunction!(through_model::predict, module)?)?;
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

/// Record `k`'s draws' stream under `seed`: the command line's for the
/// k-th record of a file.
fn posterior_stream(seed: u64, k: usize) -> twostage::models::ExperimentRng {
    twostage::models::stream_rng(seed, k as u64, twostage::models::StreamPurpose::Posterior)
}
