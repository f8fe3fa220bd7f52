//! ARX models fitted by least squares: the paper's compression, eq. (2).

use crate::InvalidSetting;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

use crate::Compressor;
use crate::error::{CompressError, Result};
use crate::fast::{contiguous_column, lagged_least_squares};
use crate::signals::{check_record, copy_window, degenerate, name};
use crate::workspace::{RANK_TOLERANCE, Workspace};
use twostage_kernels::lagged::LaggedColumn;

/// An ARX(na, nb) structure with input delay `delay`, fitted per output by
/// least squares (MISO for each output, so MIMO records work):
///
/// ```text
/// y(t) = a_1 y(t-1) + ... + a_na y(t-na)
///      + b_1 u(t-delay) + ... + b_nb u(t-delay-nb+1)   (for each input)
/// ```
///
/// The features are the coefficients, per output `[a_1..a_na, b_1..b_nb for
/// each input]`: with `delay = 1` and one input this is the paper's eq. (2)
/// ordering (`alpha_1..alpha_na` then `alpha_{na+1}..`). The regressors of
/// eq. (2) are stacked into a matrix and solved by Householder QR, never by
/// normal equations.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `na` (output lags) | none | 0..=64, `na + nb >= 1` |
/// | `nb` (input lags) | none | 0..=64 |
/// | `delay` | 1 | 0..=64 |
/// | signals (`with_signals`) | 1 input, 1 output | >= 1 each |
///
/// ```
/// use twostage_compress::{Arx, Compressor};
/// let arx = Arx::new(5, 5)?;
/// assert_eq!(arx.n_features(), 10);
/// assert_eq!(arx.to_string(), "ARX(5, 5)");
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "ArxFields")]
pub struct Arx {
    na: usize,
    nb: usize,
    delay: usize,
    n_inputs: usize,
    n_outputs: usize,
}

const MAX_ORDER: usize = 64;
/// Signals per record; far above any real use, low enough that a corrupt
/// file cannot ask for absurd allocations.
pub(crate) const MAX_SIGNALS: usize = 64;

/// What a file stores; it becomes an [`Arx`] only through the same checks
/// as [`Arx::new`], so a decoded structure is always a valid one.
#[derive(Deserialize)]
struct ArxFields {
    na: usize,
    nb: usize,
    delay: usize,
    n_inputs: usize,
    n_outputs: usize,
}

impl TryFrom<ArxFields> for Arx {
    type Error = CompressError;
    fn try_from(f: ArxFields) -> Result<Self> {
        Self::new(f.na, f.nb)?
            .with_delay(f.delay)?
            .with_signals(f.n_inputs, f.n_outputs)
    }
}

fn order_error(name: &'static str, value: usize, reason: &str) -> CompressError {
    CompressError::InvalidSetting(InvalidSetting {
        name,
        value: value.to_string(),
        reason: reason.to_string(),
    })
}

impl Arx {
    /// ARX(na, nb) with delay 1 for one input and one output.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] if an order exceeds 64 or both are 0.
    pub fn new(na: usize, nb: usize) -> Result<Self> {
        if na > MAX_ORDER {
            return Err(order_error("na", na, "at most 64"));
        }
        if nb > MAX_ORDER {
            return Err(order_error("nb", nb, "at most 64"));
        }
        if na + nb == 0 {
            return Err(order_error("na + nb", 0, "at least one lag is needed"));
        }
        Ok(Self {
            na,
            nb,
            delay: 1,
            n_inputs: 1,
            n_outputs: 1,
        })
    }

    /// The same orders with another input delay.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] if `delay > 64`.
    pub fn with_delay(mut self, delay: usize) -> Result<Self> {
        if delay > MAX_ORDER {
            return Err(order_error("delay", delay, "at most 64"));
        }
        self.delay = delay;
        Ok(self)
    }

    /// The same orders for records with several inputs or outputs.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] if a count is 0 or above 64.
    pub fn with_signals(mut self, n_inputs: usize, n_outputs: usize) -> Result<Self> {
        if n_inputs > MAX_SIGNALS || n_outputs > MAX_SIGNALS {
            return Err(order_error(
                "signals",
                n_inputs.max(n_outputs),
                "at most 64 inputs and 64 outputs",
            ));
        }
        if n_inputs == 0 && self.nb > 0 {
            return Err(order_error("inputs", 0, "nb > 0 needs at least one input"));
        }
        if n_outputs == 0 {
            return Err(order_error("outputs", 0, "at least one output is needed"));
        }
        self.n_inputs = n_inputs;
        self.n_outputs = n_outputs;
        Ok(self)
    }

    /// Output lags.
    pub fn na(&self) -> usize {
        self.na
    }
    /// Input lags.
    pub fn nb(&self) -> usize {
        self.nb
    }
    /// Input delay.
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// Features per output.
    fn per_output(&self) -> usize {
        self.na + self.n_inputs * self.nb
    }

    /// The first sample that has all its lags: `max(na, delay + nb - 1)`.
    pub fn first_sample(&self) -> usize {
        twostage_kernels::lagged::arx_first_sample(self.na, self.nb, self.delay)
    }
}

impl Arx {
    /// The specification `arx:NA,NB` (`ar:NA` without input lags), when
    /// the structure has one (not for another delay than 1).
    pub fn spec(&self) -> Option<String> {
        (self.delay == 1).then(|| match self.nb {
            0 => format!("ar:{}", self.na),
            nb => format!("arx:{},{nb}", self.na),
        })
    }
}

impl std::fmt::Display for Arx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ARX({}, {}", self.na, self.nb)?;
        if self.delay != 1 {
            write!(f, ", delay {}", self.delay)?;
        }
        f.write_str(")")
    }
}

impl Compressor for Arx {
    fn n_features(&self) -> usize {
        self.n_outputs * self.per_output()
    }

    fn compress_fast_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        let usable = alpha.len() == self.n_features()
            && inputs.ncols() == self.n_inputs
            && outputs.ncols() == self.n_outputs
            && inputs.nrows() == outputs.nrows()
            && inputs.nrows() >= self.first_sample() + self.per_output();
        if usable {
            let cols = self.per_output();
            let all = (0..self.n_outputs).all(|i| {
                let alpha_i = &mut alpha[i * cols..(i + 1) * cols];
                self.fast_output(&inputs, &outputs, i, work, alpha_i)
            });
            if all {
                return Ok(());
            }
        }
        // Anything the fast path cannot vouch for (shapes, non-finite or
        // huge samples, poor conditioning) goes through QR, which gives the
        // exact coefficients or the precise error.
        self.compress_into(inputs, outputs, work, alpha)
    }

    fn feature_names(&self) -> Vec<String> {
        let mut names = Vec::with_capacity(self.n_features());
        for i in 0..self.n_outputs {
            let y = name("y", i, self.n_outputs);
            names.extend((1..=self.na).map(|k| format!("a{k}[{y}]")));
            for j in 0..self.n_inputs {
                let u = name("u", j, self.n_inputs);
                names.extend((1..=self.nb).map(|k| format!("b{k}[{y}<-{u}]")));
            }
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
            self.n_inputs,
            self.n_outputs,
            alpha.len(),
            self.n_features(),
            start + cols,
            self,
        )?;
        let rows = n - start;
        work.prepare(rows, cols);
        for (i, alpha_i) in alpha.chunks_exact_mut(cols).enumerate() {
            let y = outputs.column(i);
            for lag in 1..=self.na {
                copy_window(work.phi.col_as_slice_mut(lag - 1), y, start - lag);
            }
            for j in 0..self.n_inputs {
                let u = inputs.column(j);
                for l in 0..self.nb {
                    let col = self.na + j * self.nb + l;
                    copy_window(work.phi.col_as_slice_mut(col), u, start - self.delay - l);
                }
            }
            copy_window(work.rhs.col_as_slice_mut(0), y, start);
            if let Some(col) = work.solve(alpha_i) {
                return Err(self.rank_error(inputs, outputs, i, col));
            }
        }
        Ok(())
    }
}

impl Arx {
    /// The fast path for one output; false when it cannot vouch for the answer.
    fn fast_output(
        &self,
        inputs: &ArrayView2<'_, f64>,
        outputs: &ArrayView2<'_, f64>,
        output: usize,
        work: &mut Workspace,
        alpha: &mut [f64],
    ) -> bool {
        // At most 1 + 64 inputs is plenty for stack storage of the slices.
        let mut signals: [&[f64]; 16] = [&[]; 16];
        if self.n_inputs + 1 > signals.len() {
            return false;
        }
        let Some(y) = contiguous_column(outputs, output) else {
            return false;
        };
        signals[0] = y;
        for j in 0..self.n_inputs {
            let Some(u) = contiguous_column(inputs, j) else {
                return false;
            };
            signals[1 + j] = u;
        }
        work.columns.clear();
        work.columns
            .extend((1..=self.na).map(|lag| LaggedColumn { signal: 0, lag }));
        for j in 0..self.n_inputs {
            work.columns.extend((0..self.nb).map(|l| LaggedColumn {
                signal: 1 + j,
                lag: self.delay + l,
            }));
        }
        let start = self.first_sample();
        lagged_least_squares(
            &signals[..=self.n_inputs],
            &work.columns,
            start,
            start,
            &mut work.fast,
            alpha,
        )
    }

    fn rank_error(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        output: usize,
        col: usize,
    ) -> CompressError {
        let (signal, which) = if col < self.na {
            (outputs.column(output), name("y", output, self.n_outputs))
        } else {
            let j = (col - self.na) / self.nb;
            (inputs.column(j), name("u", j, self.n_inputs))
        };
        let cause = degenerate(signal, &which).unwrap_or_else(|| {
            let names = self.feature_names();
            format!(
                "regressor {} is (numerically) a linear combination of the ones before it \
                 (tolerance {RANK_TOLERANCE:e} relative to its norm): the input does not \
                 excite the system enough for these orders, or the orders are too high; \
                 lower na or nb, or use a richer input",
                names[output * self.per_output() + col]
            )
        });
        CompressError::RankDeficient {
            structure: self.to_string(),
            cause,
        }
    }
}
