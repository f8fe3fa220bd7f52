//! The network's hyperparameters: unchecked ([`MlpParams`]) and checked
//! ([`Mlp`], the [`crate::Regressor`]).

use crate::InvalidSetting;
use serde::{Deserialize, Serialize};

use crate::error::{FitError, Result};

use super::MAX_WIDTH;

/// How the network's weights are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Trainer {
    /// Levenberg-Marquardt on every sample for networks under 1000
    /// weights, its curvature from the first samples where the Jacobian
    /// (samples x outputs x weights) would pass 8e6 entries; beyond 2e7
    /// entries Adam on every sample beside it, the lowest held-out error
    /// kept (a network of one hidden layer and several outputs, whose
    /// products come from its structure: Levenberg-Marquardt on as many
    /// samples as 2e7 entries take, then Adam beside it). Adam alone for
    /// larger networks.
    Auto,
    /// Levenberg-Marquardt on the full training set.
    LevenbergMarquardt,
    /// Adam (Kingma and Ba, 2015) on shuffled mini-batches.
    Adam {
        /// Step size.
        learning_rate: f64,
        /// Samples per mini-batch.
        batch_size: usize,
        /// Passes over the training set at most.
        epochs: usize,
    },
    /// L-BFGS (Nocedal and Wright, 2006) on the full training set: an
    /// iteration costs a gradient of every row, not Levenberg-Marquardt's
    /// products of a Jacobian of rows x weights.
    Lbfgs {
        /// Iterations at most.
        iterations: usize,
    },
}

impl std::fmt::Display for Trainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Auto => f.write_str("Levenberg-Marquardt (and Adam beyond its size)"),
            Self::LevenbergMarquardt => f.write_str("Levenberg-Marquardt"),
            Self::Adam {
                learning_rate,
                batch_size,
                epochs,
            } => write!(
                f,
                "Adam (step {learning_rate:e}, batches of {batch_size}, {epochs} epochs)"
            ),
            Self::Lbfgs { iterations } => write!(f, "L-BFGS (at most {iterations} iterations)"),
        }
    }
}

impl Trainer {
    /// Adam with common settings: step 1e-3, batches of 64, 500 epochs.
    pub const ADAM: Self = Self::Adam {
        learning_rate: 1e-3,
        batch_size: 64,
        epochs: 500,
    };
}

/// Hyperparameters of an MLP and its training.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `hidden` | `[10]` | 1..=4 layers, each 1..=256 units |
/// | `restarts` | 4 | >= 1 (run in parallel; the best held-out loss wins) |
/// | `max_iterations` | 300 | >= 1 LM iterations per restart |
/// | `validation_fraction` | 0.15 | in [0, 0.5]; 0 disables early stopping |
/// | `patience` | 25 | iterations without held-out improvement before stopping |
/// | `weight_decay` | 1e-6 | >= 0, L2 penalty on the weights (standardized units) |
/// | `seed` | 0 | any |
/// | `trainer` | [`Trainer::Auto`] | LM, Adam, L-BFGS, or chosen by size |
/// | `ensemble` | false (keep the best held-out network) | true: average the restarts' networks |
///
/// ```
/// use ndarray::Array2;
/// use twostage_fit::{MlpParams, Predictor, Regressor};
/// // t = sin(2 x): a linear model cannot fit it, a small network can.
/// let x = Array2::from_shape_fn((300, 1), |(i, _)| -1.5 + 3.0 * i as f64 / 299.0);
/// let t = x.mapv(|v| (2.0 * v).sin());
/// let net = MlpParams::new(&[8])?.restarts(2).seed(1).check()?.fit(x.view(), t.view())?;
/// let mut out = [0.0];
/// net.predict_into(&[0.4], &mut out)?;
/// assert!((out[0] - (0.8f64).sin()).abs() < 0.01);
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlpParams {
    pub(super) hidden: Vec<usize>,
    pub(super) restarts: usize,
    pub(super) max_iterations: usize,
    pub(super) validation_fraction: f64,
    pub(super) patience: usize,
    pub(super) weight_decay: f64,
    pub(super) seed: u64,
    pub(super) ensemble: bool,
    pub(super) trainer: Trainer,
    /// When training stops, whatever its rules say (not stored: a bound
    /// of one run, not a property of the network).
    #[serde(skip)]
    pub(super) stop_by: Option<std::time::Instant>,
}

/// Restarts of a network unless set otherwise.
pub(crate) const DEFAULT_RESTARTS: usize = 4;

impl MlpParams {
    /// A network with the given hidden layer sizes and default training.
    ///
    /// # Errors
    /// Never here: sizes are checked by [`MlpParams::check`]; the `Result`
    /// keeps the builder chain uniform.
    pub fn new(hidden: &[usize]) -> Result<Self> {
        Ok(Self {
            hidden: hidden.to_vec(),
            restarts: DEFAULT_RESTARTS,
            max_iterations: 300,
            validation_fraction: 0.15,
            patience: 25,
            weight_decay: 1e-6,
            seed: 0,
            ensemble: false,
            trainer: Trainer::Auto,
            stop_by: None,
        })
    }
    /// The hidden layer sizes.
    pub fn hidden(&self) -> &[usize] {
        &self.hidden
    }
    /// Number of seeded restarts.
    pub fn restarts(mut self, restarts: usize) -> Self {
        self.restarts = restarts;
        self
    }
    /// Iterations per restart.
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self
    }
    /// Share of the training data held out for early stopping.
    pub fn validation_fraction(mut self, fraction: f64) -> Self {
        self.validation_fraction = fraction;
        self
    }
    /// Iterations without held-out improvement before stopping.
    pub fn patience(mut self, patience: usize) -> Self {
        self.patience = patience;
        self
    }
    /// L2 penalty on the weights.
    pub fn weight_decay(mut self, decay: f64) -> Self {
        self.weight_decay = decay;
        self
    }
    /// Average the predictions of every restart's network rather than keep
    /// the one with the lowest held-out loss (the default, as in the paper).
    /// Averaging damps the spread that random initial weights cause; on the
    /// benchmark preset it lowered the RMSE by about 5%, on the car it did
    /// not help (docs/accuracy.md).
    pub fn ensemble(mut self, ensemble: bool) -> Self {
        self.ensemble = ensemble;
        self
    }
    /// The training algorithm. With Adam, `patience` counts epochs.
    pub fn trainer(mut self, trainer: Trainer) -> Self {
        self.trainer = trainer;
        self
    }

    /// The number of seeded restarts (an ensemble's members).
    pub fn n_restarts(&self) -> usize {
        self.restarts
    }
    /// Whether the restarts' networks are averaged ([`MlpParams::ensemble`]).
    pub fn is_ensemble(&self) -> bool {
        self.ensemble
    }

    /// The trainer set by [`MlpParams::trainer`] (default [`Trainer::Auto`]).
    pub fn trainer_choice(&self) -> Trainer {
        self.trainer
    }

    /// The seed of the initial weights and the held-out split.
    pub fn seed_value(&self) -> u64 {
        self.seed
    }

    /// Seed of the initial weights and of the held-out split.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Check every setting; the result can be fitted.
    ///
    /// # Errors
    /// [`FitError::InvalidSetting`] naming the first setting out of range.
    pub fn check(self) -> Result<Mlp> {
        let invalid = |name: &'static str, value: String, reason: &str| {
            FitError::InvalidSetting(InvalidSetting {
                name,
                value,
                reason: reason.into(),
            })
        };
        if self.hidden.is_empty() || self.hidden.len() > 4 {
            return Err(invalid(
                "hidden layers",
                format!("{:?}", self.hidden),
                "give 1 to 4 hidden layers",
            ));
        }
        if let Some(w) = self.hidden.iter().find(|&&w| w == 0 || w > MAX_WIDTH) {
            return Err(invalid(
                "hidden layer width",
                w.to_string(),
                "must be in 1..=256",
            ));
        }
        if self.restarts == 0 {
            return Err(invalid("restarts", "0".into(), "at least 1"));
        }
        if self.max_iterations == 0 {
            return Err(invalid("max_iterations", "0".into(), "at least 1"));
        }
        if !(0.0..=0.5).contains(&self.validation_fraction) {
            return Err(invalid(
                "validation_fraction",
                self.validation_fraction.to_string(),
                "must lie in [0, 0.5]",
            ));
        }
        if let Trainer::Adam {
            learning_rate,
            batch_size,
            epochs,
        } = self.trainer
        {
            if !(learning_rate.is_finite() && learning_rate > 0.0) {
                return Err(invalid(
                    "learning_rate",
                    learning_rate.to_string(),
                    "finite and > 0",
                ));
            }
            if batch_size == 0 || epochs == 0 {
                return Err(invalid(
                    "batch_size, epochs",
                    format!("{batch_size}, {epochs}"),
                    "both at least 1",
                ));
            }
        }
        if let Trainer::Lbfgs { iterations: 0 } = self.trainer {
            return Err(invalid("iterations", "0".into(), "at least 1"));
        }
        if !(self.weight_decay.is_finite() && self.weight_decay >= 0.0) {
            return Err(invalid(
                "weight_decay",
                self.weight_decay.to_string(),
                "finite and >= 0",
            ));
        }
        Ok(Mlp { params: self })
    }
}

/// Checked MLP hyperparameters: a [`crate::Regressor`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MlpFields")]
pub struct Mlp {
    pub(super) params: MlpParams,
}

/// What a file stores; decoding runs [`MlpParams::check`] again.
#[derive(Deserialize)]
struct MlpFields {
    params: MlpParams,
}

impl TryFrom<MlpFields> for Mlp {
    type Error = FitError;
    fn try_from(f: MlpFields) -> Result<Self> {
        f.params.check()
    }
}

impl Mlp {
    /// The hyperparameters.
    pub fn params(&self) -> &MlpParams {
        &self.params
    }

    /// The same network with another seed (initial weights, held-out split).
    pub fn with_seed(&self, seed: u64) -> Self {
        let mut params = self.params.clone();
        params.seed = seed;
        Self { params }
    }

    /// The same network, its training stopped at `stop_by` if it has not
    /// ended by then: every restart keeps its best held-out weights so far,
    /// and a restart that starts later takes one step. For a fit that must
    /// end within a time budget; the caller sees the time and decides
    /// whether such a fit is worth keeping.
    pub fn stopped_by(&self, stop_by: std::time::Instant) -> Self {
        let mut params = self.params.clone();
        params.stop_by = Some(stop_by);
        Self { params }
    }
}
