//! Charts simulated elsewhere, read from files, in one of two layouts:
//!
//! - CSV, as `twostage simulate --count --out-dir` writes it. DIR/truth.csv
//!   holds `experiment,<parameter names>`, one row per experiment;
//!   DIR/data.csv holds `experiment,<input names>,<output names>`, one row
//!   per sample, each experiment's rows together, experiments in any order.
//! - NumPy, for large charts: DIR/theta.npy `[m, q]`, DIR/outputs.npy
//!   `[m, N, n_y]` and, for a model with inputs, DIR/inputs.npy
//!   `[m, N, n_u]`; float64, C order (numpy's defaults).
//!
//! Records are read one at a time, so memory stays O(m (q + n)) for m
//! experiments, whatever their length. Every problem names the file, and
//! the line and column of a CSV.

use std::collections::HashMap;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use twostage_models::{IoData, ModelSpec, SignalColumn};

use crate::chart_arrays::ChartArrays;
use crate::error::{Error, Result};

/// A chart on disk, its parameters read and checked, its records read on
/// demand; or a chart of arrays in memory ([`ChartFiles::from_arrays`]),
/// read the same way.
///
/// ```no_run
/// use twostage_sources::{ChartFiles, ModelFile};
/// let model = ModelFile::load("sir.toml")?;
/// let chart = ChartFiles::open("runs/sir", model.spec())?;
/// println!("{} experiments", chart.len());
/// # Ok::<(), twostage_sources::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct ChartFiles {
    dir: PathBuf,
    /// How the estimator file names the chart, when not by its folder.
    label: Option<String>,
    ids: Vec<String>,
    thetas: Vec<f64>,
    q: usize,
    stored: Stored,
}

/// Where a chart's records are.
#[derive(Debug, Clone)]
enum Stored {
    /// DIR/data.csv.
    Csv,
    /// DIR/inputs.npy and DIR/outputs.npy.
    Numpy,
    /// Arrays in memory.
    Memory(Arc<ChartArrays>),
}

impl ChartFiles {
    /// Read DIR/truth.csv and check it against the model.
    ///
    /// # Errors
    /// [`Error::ChartFile`] naming the file, line and column of the first
    /// problem: a header without the model's parameter names, a value that
    /// is not a finite number, an experiment listed twice, no experiment.
    pub fn open(dir: impl AsRef<Path>, spec: &ModelSpec) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let has = |name: &str| dir.join(name).is_file();
        if !has("truth.csv") && has("theta.npy") {
            return Self::open_numpy(dir, spec);
        }
        let missing = match (has("truth.csv"), has("data.csv")) {
            (true, true) => None,
            (true, false) => Some("truth.csv is there but data.csv, its records, is not"),
            (false, _) if dir.is_dir() => Some("no chart in this folder"),
            (false, _) => Some("no such folder"),
        };
        if let Some(what) = missing {
            return Err(Located::new(&dir).error(
                None,
                format!(
                    "{what}: a chart is truth.csv and data.csv (as twostage simulate --count \
                     --out-dir writes them), or theta.npy, outputs.npy and, for a model with \
                     inputs, inputs.npy"
                ),
            ));
        }
        let path = dir.join("truth.csv");
        let file = Located::new(&path);
        let q = spec.n_params();
        let expected: Vec<&str> = std::iter::once("experiment")
            .chain(spec.param_names().iter().map(String::as_str))
            .collect();
        let (mut ids, mut thetas, mut seen) = (Vec::new(), Vec::new(), HashMap::new());
        let mut header = false;
        file.rows(|number, fields| {
            if !header {
                header = true;
                if fields.iter().ne(expected.iter().copied()) {
                    return Err(file.error(
                        Some(number),
                        format!(
                            "header '{}': expected '{}' (the model's parameters, in order)",
                            crate::csv_rows::excerpt(&fields.iter().collect::<Vec<_>>().join(",")),
                            expected.join(",")
                        ),
                    ));
                }
                return Ok(());
            }
            if fields.len() != q + 1 {
                return Err(file.error(
                    Some(number),
                    format!("{} values, the header has {}", fields.len(), q + 1),
                ));
            }
            let id = fields[0].to_string();
            if let Some(first) = seen.insert(id.clone(), number) {
                return Err(file.error(
                    Some(number),
                    format!("experiment '{id}' again (first on line {first})"),
                ));
            }
            for (j, field) in fields.iter().skip(1).enumerate() {
                thetas.push(file.number(field, number, expected[j + 1])?);
            }
            ids.push(id);
            Ok(())
        })?;
        if !header {
            return Err(file.error(None, "the file is empty; expected a header".into()));
        }
        if ids.is_empty() {
            return Err(file.error(None, "no experiment: the header is alone".into()));
        }
        Ok(Self {
            dir,
            label: None,
            ids,
            thetas,
            q,
            stored: Stored::Csv,
        })
    }

    /// Read DIR/theta.npy and check the shapes of the record arrays.
    fn open_numpy(dir: PathBuf, spec: &ModelSpec) -> Result<Self> {
        let q = spec.n_params();
        let (theta_file, shape) = npy(&dir.join("theta.npy"))?;
        let m = shape.first().copied().unwrap_or(0);
        let named = Located::new(&dir).join("theta.npy");
        if shape.len() != 2 || shape[1] != q || m == 0 {
            return Err(named.error(
                None,
                format!(
                    "shape {shape:?}: expected [m, {q}] (m experiments of the model's {q} \
                     parameters), m >= 1"
                ),
            ));
        }
        let thetas = read_all(theta_file, &named)?;
        if let Some(k) = thetas.iter().position(|v| !v.is_finite()) {
            return Err(named.error(
                None,
                format!(
                    "theta[{}, {}] = {} is not a finite number",
                    k / q,
                    k % q,
                    thetas[k]
                ),
            ));
        }
        let chart = Self {
            dir,
            label: None,
            ids: (0..m).map(|i| i.to_string()).collect(),
            thetas,
            q,
            stored: Stored::Numpy,
        };
        // Shapes now, so that a wrong file fails before any work.
        for (name, width) in chart.record_arrays(spec) {
            let (_, shape) = npy(&chart.dir.join(name))?;
            let want = [m, spec.n_samples(), width];
            if shape != want {
                return Err(Located::new(&chart.dir).join(name).error(
                    None,
                    format!(
                        "shape {shape:?}: expected {want:?} (experiments, samples, signals; \
                         theta.npy has {m} experiments, the model {} samples)",
                        spec.n_samples()
                    ),
                ));
            }
        }
        Ok(chart)
    }

    /// The record arrays of a NumPy chart and their signal counts.
    fn record_arrays(&self, spec: &ModelSpec) -> Vec<(&'static str, usize)> {
        let (n_u, n_y) = (spec.input_names().len(), spec.output_names().len());
        let mut arrays = vec![("outputs.npy", n_y)];
        if n_u > 0 {
            arrays.insert(0, ("inputs.npy", n_u));
        }
        arrays
    }

    /// Number of experiments m.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the chart is empty (never: `open` refuses that).
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// A chart given as arrays (`theta [m, q]`, `inputs [m, N, n_u]` for a
    /// model with inputs, `outputs [m, N, n_y]`), checked against `spec`
    /// as a chart's files are, named `label` in the estimator file: its
    /// records are those of the same arrays saved as a NumPy chart, in
    /// the same order.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use ndarray::{Array2, Array3};
    /// use twostage_models::{Benchmark, Simulator};
    /// use twostage_sources::{ChartArrays, ChartFiles};
    /// let spec = Benchmark::new().spec().clone();
    /// let n = spec.n_samples();
    /// let arrays = ChartArrays {
    ///     theta: Array2::from_elem((3, 1), 0.2),
    ///     inputs: Some(Array3::zeros((3, n, 1))),
    ///     outputs: Array3::zeros((3, n, 1)),
    /// };
    /// let chart = ChartFiles::from_arrays(Arc::new(arrays.clone()), &spec, "three runs")?;
    /// assert_eq!((chart.len(), chart.theta(2), chart.describe().as_str()), (3, &[0.2][..], "three runs"));
    /// let mut bad = arrays;
    /// bad.outputs[[1, 4, 0]] = f64::NAN;
    /// let refused = ChartFiles::from_arrays(Arc::new(bad), &spec, "three runs").unwrap_err();
    /// assert_eq!(refused.to_string(), "chart: outputs[1, 4, 0] = NaN is not a finite number");
    /// # Ok::<(), twostage_sources::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::ChartFile`] naming the array: a shape that is not the
    /// model's, no experiment, a value that is not finite (its index).
    pub fn from_arrays(
        arrays: Arc<ChartArrays>,
        spec: &ModelSpec,
        label: impl Into<String>,
    ) -> Result<Self> {
        arrays.check(spec)?;
        Ok(Self {
            dir: PathBuf::new(),
            label: Some(label.into()),
            ids: (0..arrays.len()).map(|i| i.to_string()).collect(),
            thetas: arrays.thetas(),
            q: spec.n_params(),
            stored: Stored::Memory(arrays),
        })
    }

    /// Name the chart in the estimator file by `label` instead of its
    /// folder.
    pub fn labelled(mut self, label: impl Into<String>) -> Self {
        self.label = Some(label.into());
        self
    }

    /// How the estimator file names the chart: its label, or its folder.
    pub fn describe(&self) -> String {
        self.label
            .clone()
            .unwrap_or_else(|| self.dir.display().to_string())
    }

    /// The parameters of experiment `row` (in truth.csv's order).
    pub fn theta(&self, row: usize) -> &[f64] {
        &self.thetas[row * self.q..(row + 1) * self.q]
    }

    /// Read DIR/data.csv and hand each record to `visit` with its row in
    /// truth.csv, in the file's order.
    ///
    /// # Errors
    /// [`Error::ChartFile`] for the first problem in the file (a header
    /// without the model's signals, a value that is not a finite number, a
    /// record of another length, an experiment not in truth.csv, one whose
    /// rows are split, one missing); `visit`'s own errors.
    pub fn for_each_record(
        &self,
        spec: &ModelSpec,
        mut visit: impl FnMut(usize, &IoData) -> Result<()>,
    ) -> Result<()> {
        match &self.stored {
            Stored::Numpy => return self.for_each_numpy_record(spec, visit),
            Stored::Memory(arrays) => return arrays.for_each_record(visit),
            Stored::Csv => {}
        }
        let path = self.dir.join("data.csv");
        let file = Located::new(&path);
        let rows: HashMap<&str, usize> = self
            .ids
            .iter()
            .enumerate()
            .map(|(row, id)| (id.as_str(), row))
            .collect();
        let (n, n_u, n_y) = (
            spec.n_samples(),
            spec.input_names().len(),
            spec.output_names().len(),
        );
        let mut done = vec![false; self.ids.len()];
        let mut record = IoData::zeros(n, n_u, n_y);
        // The experiment being read: its row, first line, and samples so far.
        let mut current: Option<(usize, usize, usize)> = None;
        let mut finish =
            |current: Option<(usize, usize, usize)>, record: &IoData, at: usize| -> Result<()> {
                if let Some((row, first, k)) = current {
                    if k != n {
                        return Err(file.error(
                            Some(at),
                            format!(
                                "experiment '{}' (from line {first}) has {k} samples, the model's \
                             records have {n}",
                                self.ids[row]
                            ),
                        ));
                    }
                    visit(row, record)?;
                }
                Ok(())
            };
        let mut columns: Option<Vec<(SignalColumn, String)>> = None;
        let mut last_line = 0;
        file.rows(|number, fields| {
            last_line = number;
            let Some(columns) = &columns else {
                let header = fields.iter().collect::<Vec<_>>().join(",");
                columns = Some(signal_columns(spec, &header).ok_or_else(|| {
                    let signals: Vec<&str> = spec
                        .input_names()
                        .iter()
                        .chain(spec.output_names())
                        .map(String::as_str)
                        .collect();
                    let given: Vec<&str> = fields.iter().collect();
                    let difference = match given.split_first() {
                        Some((&"experiment", rest)) => {
                            crate::record_file::header_difference(rest, &signals)
                        }
                        _ => "the first column must be experiment".to_string(),
                    };
                    file.error(
                        Some(number),
                        format!(
                            "header '{}': expected experiment, then the inputs and outputs \
                             ({}), or u,y as `twostage simulate` writes them: {}",
                            crate::csv_rows::excerpt(&header),
                            signals.join(","),
                            difference
                        ),
                    )
                })?);
                return Ok(());
            };
            if fields.len() != columns.len() + 1 {
                return Err(file.error(
                    Some(number),
                    format!(
                        "{} values, the header has {}",
                        fields.len(),
                        columns.len() + 1
                    ),
                ));
            }
            let id = &fields[0];
            let same = current.is_some_and(|(row, _, _)| self.ids[row] == id);
            if !same {
                finish(current, &record, number)?;
                let row = *rows.get(id).ok_or_else(|| {
                    file.error(
                        Some(number),
                        format!("experiment '{id}' is not in truth.csv"),
                    )
                })?;
                if done[row] {
                    return Err(file.error(
                        Some(number),
                        format!(
                            "experiment '{id}' resumes after other experiments: keep each \
                             experiment's rows together"
                        ),
                    ));
                }
                done[row] = true;
                current = Some((row, number, 0));
            }
            let Some((_, _, k)) = current.as_mut() else {
                return Ok(());
            };
            if *k >= n {
                return Err(file.error(
                    Some(number),
                    format!("experiment '{id}' has more than the model's {n} samples"),
                ));
            }
            for (c, field) in fields.iter().skip(1).enumerate() {
                let value = file.number(field, number, &columns[c].1)?;
                match columns[c].0 {
                    SignalColumn::Input(j) => record.input_mut(j)[*k] = value,
                    SignalColumn::Output(j) => record.output_mut(j)[*k] = value,
                }
            }
            *k += 1;
            Ok(())
        })?;
        if columns.is_none() {
            return Err(file.error(None, "the file is empty; expected a header".into()));
        }
        finish(current, &record, last_line + 1)?;
        if let Some(row) = done.iter().position(|d| !d) {
            let missing = done.iter().filter(|d| !**d).count();
            return Err(file.error(
                None,
                format!(
                    "{missing} experiment(s) of truth.csv have no rows, the first '{}'",
                    self.ids[row]
                ),
            ));
        }
        Ok(())
    }
}

impl ChartFiles {
    /// The records of a NumPy chart, read in step from inputs.npy and
    /// outputs.npy, one record's values at a time.
    fn for_each_numpy_record(
        &self,
        spec: &ModelSpec,
        mut visit: impl FnMut(usize, &IoData) -> Result<()>,
    ) -> Result<()> {
        let (n, n_u, n_y) = (
            spec.n_samples(),
            spec.input_names().len(),
            spec.output_names().len(),
        );
        let mut readers = Vec::new();
        for (name, _) in self.record_arrays(spec) {
            let path = self.dir.join(name);
            let (file, _) = npy(&path)?;
            let located = Located::new(&self.dir).join(name);
            let values = file.data::<f64>().map_err(|e| {
                located.error(None, format!("{e}: save float64 arrays (numpy's default)"))
            })?;
            readers.push((located, values));
        }
        let mut record = IoData::zeros(n, n_u, n_y);
        for row in 0..self.ids.len() {
            for (located, values) in &mut readers {
                let inputs = located.path.ends_with("inputs.npy");
                let width = if inputs { n_u } else { n_y };
                for k in 0..n {
                    for j in 0..width {
                        let value = values
                            .next()
                            .ok_or_else(|| located.error(None, "ends early".into()))?
                            .map_err(|cause| Error::Io {
                                path: located.path.display().to_string(),
                                cause,
                            })?;
                        if !value.is_finite() {
                            return Err(located.error(
                                None,
                                format!("[{row}, {k}, {j}] = {value} is not a finite number"),
                            ));
                        }
                        if inputs {
                            record.input_mut(j)[k] = value;
                        } else {
                            record.output_mut(j)[k] = value;
                        }
                    }
                }
            }
            visit(row, &record)?;
        }
        Ok(())
    }
}

/// The longest .npy header read: NumPy's own `np.load` refuses longer
/// ones by default (`max_header_size`, NumPy 1.24 on).
const MAX_NPY_HEADER: usize = 10_000;

/// Refuses an .npy header that the NumPy reader would take apart badly:
/// a length word beyond [`MAX_NPY_HEADER`] (it allocates what the word
/// says) or brackets nested deeper than a dictionary holding a tuple (it
/// parses nesting in time exponential in its depth), which is all a
/// header NumPy writes for an array of plain numbers holds.
fn check_npy_preamble(bytes: &[u8]) -> std::result::Result<(), String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || !bytes.starts_with(MAGIC) {
        return Ok(()); // The reader itself says what is wrong.
    }
    let (length, start) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => {
            let word = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
            (usize::try_from(word).unwrap_or(usize::MAX), 12)
        }
        _ => return Ok(()),
    };
    if length > MAX_NPY_HEADER {
        return Err(format!(
            "its header claims {length} bytes, where NumPy writes and reads at most \
             {MAX_NPY_HEADER}: the file is damaged or not written by NumPy"
        ));
    }
    // A dictionary holding one tuple: two levels of brackets.
    let mut depth = 0usize;
    for &byte in bytes.iter().skip(start).take(length) {
        match byte {
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth > 2 {
                    return Err(
                        "its header nests brackets deeper than a dictionary holding \
                                a shape: the file is damaged or not written by NumPy"
                            .into(),
                    );
                }
            }
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    Ok(())
}

/// An .npy file opened, its header read: the reader and the shape.
fn npy(path: &Path) -> Result<(npyz::NpyFile<BufReader<std::fs::File>>, Vec<usize>)> {
    use std::io::{Read, Seek};
    let io = |cause| Error::Io {
        path: path.display().to_string(),
        cause,
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut preamble = Vec::with_capacity(12 + MAX_NPY_HEADER);
    (&mut file)
        .take((12 + MAX_NPY_HEADER) as u64)
        .read_to_end(&mut preamble)
        .map_err(io)?;
    check_npy_preamble(&preamble).map_err(|message| Error::ChartFile {
        file: path.display().to_string(),
        line: None,
        message: format!("not a NumPy .npy file: {message}"),
    })?;
    file.rewind().map_err(io)?;
    let npy = npyz::NpyFile::new(BufReader::new(file)).map_err(|e| Error::ChartFile {
        file: path.display().to_string(),
        line: None,
        message: format!("not a NumPy .npy file ({e})"),
    })?;
    if npy.order() != npyz::Order::C {
        return Err(Error::ChartFile {
            file: path.display().to_string(),
            line: None,
            message: "stored in Fortran order: save np.ascontiguousarray(a)".into(),
        });
    }
    let shape: Vec<usize> = npy.shape().iter().map(|&d| d as usize).collect();
    // The values the shape declares must be in the file, before a reader
    // sizes anything by the shape. In f64: a forged shape overflows usize.
    let item = npy.dtype().num_bytes().unwrap_or(1) as f64;
    let declared = shape.iter().fold(item, |bytes, &d| bytes * d as f64);
    let size = std::fs::metadata(path).map_err(io)?.len();
    if declared > size as f64 {
        return Err(Error::ChartFile {
            file: path.display().to_string(),
            line: None,
            message: format!(
                "its shape {shape:?} declares {} of values, the file holds {}: \
                 it was cut short, or its header is damaged",
                twostage_models::readable_bytes(declared),
                twostage_models::readable_bytes(size as f64)
            ),
        });
    }
    Ok((npy, shape))
}

/// Every value of a small .npy file (theta), as float64.
fn read_all(
    npy: npyz::NpyFile<BufReader<std::fs::File>>,
    located: &Located<'_>,
) -> Result<Vec<f64>> {
    npy.into_vec::<f64>()
        .map_err(|e| located.error(None, format!("{e}: save float64 arrays (numpy's default)")))
}

/// The data columns after `experiment`, by the model's signal names or by
/// the generic `u,y` (`u1,u2,...,y1,...`) of `twostage simulate`, each with
/// its name for messages; `None` if the header is neither.
fn signal_columns(spec: &ModelSpec, header: &str) -> Option<Vec<(SignalColumn, String)>> {
    let found: Vec<&str> = header.split(',').map(str::trim).collect();
    let (first, rest) = found.split_first()?;
    if *first != "experiment" {
        return None;
    }
    let columns = twostage_models::signal_columns(rest, spec.input_names(), spec.output_names())?;
    Some(
        columns
            .into_iter()
            .zip(rest)
            .map(|(column, name)| (column, (*name).to_string()))
            .collect(),
    )
}

/// A file being read, for its messages.
struct Located<'p> {
    path: std::borrow::Cow<'p, Path>,
}

impl<'p> Located<'p> {
    fn new(path: &'p Path) -> Self {
        Self {
            path: std::borrow::Cow::Borrowed(path),
        }
    }

    /// The file `name` in this folder.
    fn join(&self, name: &str) -> Located<'static> {
        Located {
            path: std::borrow::Cow::Owned(self.path.join(name)),
        }
    }

    fn error(&self, line: Option<usize>, message: String) -> Error {
        Error::ChartFile {
            file: self.path.display().to_string(),
            line,
            message,
        }
    }

    /// Visit the file's rows (the header first) with their 1-based line
    /// numbers and trimmed fields.
    fn rows(&self, visit: impl FnMut(usize, &csv::StringRecord) -> Result<()>) -> Result<()> {
        let file = std::fs::File::open(&self.path).map_err(|cause| Error::Io {
            path: self.path.display().to_string(),
            cause,
        })?;
        crate::csv_rows::for_each_row(BufReader::new(file), visit, |line, message| {
            self.error(line, format!("cannot be read: {message}"))
        })
    }

    fn number(&self, field: &str, line: usize, column: &str) -> Result<f64> {
        field
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                self.error(
                    Some(line),
                    format!("column {column}: '{field}' is not a finite number"),
                )
            })
    }
}
