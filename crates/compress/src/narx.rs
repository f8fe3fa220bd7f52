//! Polynomial NARX models fitted by least squares: the paper's suggestion
//! for systems too nonlinear for ARX (Section 4.3).

use crate::InvalidSetting;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::Compressor;
use crate::arx::MAX_SIGNALS;
use crate::error::{CompressError, Result};
use crate::signals::{check_record, degenerate, name};
use crate::workspace::{RANK_TOLERANCE, Workspace};

/// One monomial: the product of a lower-degree monomial (`parent`, or
/// none for degree 1) and one lagged variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
struct Monomial {
    parent: Option<usize>,
    variable: usize,
    degree: usize,
}

/// A polynomial NARX(na, nb, degree) structure, fitted per output by least
/// squares. The regressors are a constant and every monomial of degree 1 to
/// `degree` in the lagged variables `y(t-1..t-na)` and, for each input,
/// `u(t-delay..t-delay-nb+1)`, or only their pure powers. Before forming
/// monomials each signal is divided by a fixed scale (its typical RMS), so
/// that powers of different signals have similar sizes and the regressors
/// stay well conditioned; the features are the coefficients in those
/// scaled units.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `na`, `nb` | none | 0..=16, `na + nb >= 1` |
/// | `degree` | none | 1..=5 |
/// | `delay` | 1 | 0..=64 |
/// | `pure_powers` | false (all cross terms) | true: `x_v^k` only |
/// | scales | 1 for every signal | finite, > 0 |
///
/// ```
/// use twostage_compress::{Compressor, Narx};
/// let narx = Narx::new(2, 2, 3)?;
/// // A constant and the monomials of degree 1..3 in 4 variables: C(7, 3) = 35.
/// assert_eq!(narx.n_features(), 35);
/// assert_eq!(Narx::new(2, 2, 3)?.pure_powers(true).n_features(), 1 + 4 * 3);
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "NarxFields")]
pub struct Narx {
    na: usize,
    nb: usize,
    delay: usize,
    degree: usize,
    pure_powers: bool,
    input_scales: Vec<f64>,
    output_scales: Vec<f64>,
    monomials: Vec<Monomial>,
}

/// What a file stores; it becomes a [`Narx`] only by rebuilding it through
/// the constructors, and its monomials must be the ones they build.
#[derive(Deserialize)]
struct NarxFields {
    na: usize,
    nb: usize,
    delay: usize,
    degree: usize,
    pure_powers: bool,
    input_scales: Vec<f64>,
    output_scales: Vec<f64>,
    monomials: Vec<Monomial>,
}

impl TryFrom<NarxFields> for Narx {
    type Error = CompressError;
    fn try_from(f: NarxFields) -> Result<Self> {
        let narx = Self::new(f.na, f.nb, f.degree)?
            .pure_powers(f.pure_powers)
            .with_delay(f.delay)?
            .with_scales(&f.input_scales, &f.output_scales)?;
        if narx.monomials != f.monomials {
            return Err(setting(
                "monomials",
                f.monomials.len(),
                "do not match the stored orders and degree (the data is corrupted)",
            ));
        }
        Ok(narx)
    }
}

const MAX_LAGS: usize = 16;
const MAX_DEGREE: usize = 5;

fn setting(name: &'static str, value: impl ToString, reason: &str) -> CompressError {
    CompressError::InvalidSetting(InvalidSetting {
        name,
        value: value.to_string(),
        reason: reason.to_string(),
    })
}

impl Narx {
    /// NARX(na, nb) of polynomial degree `degree`, delay 1, one input and
    /// one output, unit scales, all cross terms.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for orders above 16, no lags, or a
    /// degree outside 1..=5.
    pub fn new(na: usize, nb: usize, degree: usize) -> Result<Self> {
        if na > MAX_LAGS || nb > MAX_LAGS {
            return Err(setting(
                "na, nb",
                format!("{na}, {nb}"),
                "at most 16 lags each",
            ));
        }
        if na + nb == 0 {
            return Err(setting("na + nb", 0, "at least one lag is needed"));
        }
        if !(1..=MAX_DEGREE).contains(&degree) {
            return Err(setting("degree", degree, "must lie in 1..=5"));
        }
        let mut narx = Self {
            na,
            nb,
            delay: 1,
            degree,
            pure_powers: false,
            input_scales: vec![1.0],
            output_scales: vec![1.0],
            monomials: Vec::new(),
        };
        narx.build_monomials();
        Ok(narx)
    }

    /// Keep only pure powers `x_v^k` (no cross terms).
    pub fn pure_powers(mut self, pure: bool) -> Self {
        self.pure_powers = pure;
        self.build_monomials();
        self
    }

    /// Another input delay.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] if `delay > 64`.
    pub fn with_delay(mut self, delay: usize) -> Result<Self> {
        if delay > 64 {
            return Err(setting("delay", delay, "at most 64"));
        }
        self.delay = delay;
        Ok(self)
    }

    /// Scales of the signals (one per input, one per output); this also
    /// sets the number of signals.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for a scale that is not finite and
    /// positive, or no output.
    pub fn with_scales(mut self, input_scales: &[f64], output_scales: &[f64]) -> Result<Self> {
        if output_scales.is_empty() || (input_scales.is_empty() && self.nb > 0) {
            return Err(setting(
                "scales",
                format!(
                    "{} inputs, {} outputs",
                    input_scales.len(),
                    output_scales.len()
                ),
                "give one scale per signal, at least one output (and one input when nb > 0)",
            ));
        }
        if input_scales.len() > MAX_SIGNALS || output_scales.len() > MAX_SIGNALS {
            return Err(setting(
                "scales",
                input_scales.len().max(output_scales.len()),
                "at most 64 inputs and 64 outputs",
            ));
        }
        if let Some(s) = input_scales
            .iter()
            .chain(output_scales)
            .find(|s| !(s.is_finite() && **s > 0.0))
        {
            return Err(setting("scale", s, "must be finite and > 0"));
        }
        self.input_scales = input_scales.to_vec();
        self.output_scales = output_scales.to_vec();
        self.build_monomials();
        Ok(self)
    }

    /// The signal scales, inputs then outputs.
    pub fn scales(&self) -> (&[f64], &[f64]) {
        (&self.input_scales, &self.output_scales)
    }

    /// Whether every scale is still the default 1 (not yet calibrated).
    pub fn has_unit_scales(&self) -> bool {
        self.input_scales
            .iter()
            .chain(&self.output_scales)
            .all(|s| (*s - 1.0).abs() < f64::EPSILON)
    }

    fn n_inputs(&self) -> usize {
        self.input_scales.len()
    }

    fn n_outputs(&self) -> usize {
        self.output_scales.len()
    }

    /// Lagged variables per output: y lags, then each input's lags.
    fn n_variables(&self) -> usize {
        self.na + self.n_inputs() * self.nb
    }

    fn first_sample(&self) -> usize {
        let reach = if self.nb == 0 {
            0
        } else {
            self.delay + self.nb - 1
        };
        self.na.max(reach)
    }

    /// Regressors per output: the constant and the monomials.
    fn per_output(&self) -> usize {
        1 + self.monomials.len()
    }

    fn build_monomials(&mut self) {
        let p = self.n_variables();
        let mut monomials: Vec<Monomial> = (0..p)
            .map(|variable| Monomial {
                parent: None,
                variable,
                degree: 1,
            })
            .collect();
        let mut previous = 0..monomials.len();
        for degree in 2..=self.degree {
            let start = monomials.len();
            for parent in previous.clone() {
                let last = monomials[parent].variable;
                let variables = if self.pure_powers {
                    last..last + 1
                } else {
                    last..p
                };
                for variable in variables {
                    monomials.push(Monomial {
                        parent: Some(parent),
                        variable,
                        degree,
                    });
                }
            }
            previous = start..monomials.len();
        }
        self.monomials = monomials;
    }

    /// Name of lagged variable v, e.g. `y(t-1)` or `u2(t-3)`.
    fn variable_name(&self, v: usize, output: usize) -> String {
        if v < self.na {
            format!("{}(t-{})", name("y", output, self.n_outputs()), v + 1)
        } else {
            let j = (v - self.na) / self.nb;
            let lag = self.delay + (v - self.na) % self.nb;
            format!("{}(t-{lag})", name("u", j, self.n_inputs()))
        }
    }

    fn monomial_name(&self, m: usize, output: usize) -> String {
        let mut factors = Vec::new();
        let mut current = Some(m);
        while let Some(i) = current {
            factors.push(self.variable_name(self.monomials[i].variable, output));
            current = self.monomials[i].parent;
        }
        factors.reverse();
        factors.join("*")
    }
}

impl Narx {
    /// The specification `narx:NA,NB,DEG`, when the structure has one (not
    /// for pure powers or another delay than 1).
    pub fn spec(&self) -> Option<String> {
        (!self.pure_powers && self.delay == 1)
            .then(|| format!("narx:{},{},{}", self.na, self.nb, self.degree))
    }
}

impl std::fmt::Display for Narx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NARX({}, {}, degree {}", self.na, self.nb, self.degree)?;
        if self.pure_powers {
            f.write_str(", pure powers")?;
        }
        if self.delay != 1 {
            write!(f, ", delay {}", self.delay)?;
        }
        f.write_str(")")
    }
}

impl Compressor for Narx {
    fn n_features(&self) -> usize {
        self.n_outputs() * self.per_output()
    }

    fn feature_names(&self) -> Vec<String> {
        let mut names = Vec::with_capacity(self.n_features());
        for i in 0..self.n_outputs() {
            let y = name("y", i, self.n_outputs());
            names.push(format!("1[{y}]"));
            names.extend(
                (0..self.monomials.len()).map(|m| format!("{}[{y}]", self.monomial_name(m, i))),
            );
        }
        names
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let start = self.first_sample();
        let cols = self.per_output();
        let n = check_record(
            inputs,
            outputs,
            self.n_inputs(),
            self.n_outputs(),
            alpha.len(),
            self.n_features(),
            start + cols,
            self,
        )?;
        let rows = n - start;
        work.prepare(rows, cols);
        for (i, alpha_i) in alpha.chunks_exact_mut(cols).enumerate() {
            let y = outputs.column(i);
            let y_scale = self.output_scales[i];
            work.phi.col_as_slice_mut(0).fill(1.0);
            for (m, mono) in self.monomials.iter().enumerate() {
                // The variable's window, scaled.
                let v = mono.variable;
                let (signal, scale, lag) = if v < self.na {
                    (y, y_scale, v + 1)
                } else {
                    let j = (v - self.na) / self.nb;
                    (
                        inputs.column(j),
                        self.input_scales[j],
                        self.delay + (v - self.na) % self.nb,
                    )
                };
                let column = m + 1;
                match mono.parent {
                    None => {
                        let dst = work.phi.col_as_slice_mut(column);
                        for (d, s) in dst.iter_mut().zip(signal.iter().skip(start - lag)) {
                            *d = s / scale;
                        }
                    }
                    Some(parent) => {
                        // Column of the parent monomial times the variable.
                        for r in 0..rows {
                            let value = work.phi[(r, parent + 1)] * signal[start - lag + r] / scale;
                            work.phi[(r, column)] = value;
                        }
                    }
                }
            }
            let target = work.rhs.col_as_slice_mut(0);
            for (d, s) in target.iter_mut().zip(y.iter().skip(start)) {
                *d = s / y_scale;
            }
            if let Some(col) = work.solve(alpha_i) {
                return Err(self.rank_error(inputs, outputs, i, col));
            }
        }
        Ok(())
    }
}

impl Narx {
    fn rank_error(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        output: usize,
        col: usize,
    ) -> CompressError {
        let cause = if col == 0 {
            None
        } else {
            let v = self.monomials[col - 1].variable;
            if v < self.na {
                degenerate(outputs.column(output), &name("y", output, self.n_outputs()))
            } else {
                let j = (v - self.na) / self.nb;
                degenerate(inputs.column(j), &name("u", j, self.n_inputs()))
            }
        };
        let cause = cause.unwrap_or_else(|| {
            format!(
                "regressor {} is (numerically) a combination of the ones before it (tolerance \
                 {RANK_TOLERANCE:e}): the input does not excite the system enough for this \
                 structure (a binary input makes u^2 constant, for instance); lower the degree, \
                 use pure powers, or use a richer input",
                self.feature_names()[output * self.per_output() + col]
            )
        });
        CompressError::RankDeficient {
            structure: self.to_string(),
            cause,
        }
    }
}

/// The root mean square of each column: the natural scale of a signal for
/// [`Narx::with_scales`] (1 for an all-zero column).
///
/// ```
/// use ndarray::array;
/// let rms = twostage_compress::signal_rms(array![[3.0], [-4.0]].view());
/// assert!((rms[0] - 12.5f64.sqrt()).abs() < 1e-12);
/// ```
pub fn signal_rms(signals: ArrayView2<'_, f64>) -> Vec<f64> {
    signals
        .columns()
        .into_iter()
        .map(|c| {
            let rms = (c.iter().map(|v| v * v).sum::<f64>() / c.len().max(1) as f64).sqrt();
            if rms > 0.0 && rms.is_finite() {
                rms
            } else {
                1.0
            }
        })
        .collect()
}
