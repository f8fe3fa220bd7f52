//! Small feed-forward networks (tanh hidden layers, linear outputs) trained
//! by Levenberg-Marquardt with a held-out split for early stopping and
//! seeded restarts run in parallel.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use ndarray::{Array2, ArrayView2};
use rand::RngExt;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use std::ops::ControlFlow;

use twostage_kernels::layer::{Activation, dense_layer};

use crate::check;
use crate::error::{FitError, Result};
use crate::levenberg_marquardt::{
    Damping, LeastSquaresProblem, LevenbergMarquardt, TerminationReason,
};
use crate::standardize::Standardizer;
use crate::{Predictor, Regressor};

/// The widest layer supported: prediction keeps activations on the stack.
pub const MAX_WIDTH: usize = 256;

/// How the network's weights are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Trainer {
    /// Levenberg-Marquardt while its Jacobian (samples x outputs x weights)
    /// stays under 2e7 entries and the network under 1000 weights, Adam
    /// beyond.
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
/// | `trainer` | [`Trainer::Auto`] | LM, Adam, or chosen by size |
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
    hidden: Vec<usize>,
    restarts: usize,
    max_iterations: usize,
    validation_fraction: f64,
    patience: usize,
    weight_decay: f64,
    seed: u64,
    ensemble: bool,
    trainer: Trainer,
}

impl MlpParams {
    /// A network with the given hidden layer sizes and default training.
    ///
    /// # Errors
    /// Never here: sizes are checked by [`MlpParams::check`]; the `Result`
    /// keeps the builder chain uniform.
    pub fn new(hidden: &[usize]) -> Result<Self> {
        Ok(Self {
            hidden: hidden.to_vec(),
            restarts: 4,
            max_iterations: 300,
            validation_fraction: 0.15,
            patience: 25,
            weight_decay: 1e-6,
            seed: 0,
            ensemble: false,
            trainer: Trainer::Auto,
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
    /// The seed set by [`MlpParams::seed`].
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
        let invalid = |name: &'static str, value: String, reason: &str| FitError::InvalidSetting {
            name,
            value,
            reason: reason.into(),
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

/// Checked MLP hyperparameters: a [`Regressor`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MlpFields")]
pub struct Mlp {
    params: MlpParams,
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
}

/// How one restart went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RestartReport {
    /// Restart index.
    pub restart: usize,
    /// Iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub reason: TerminationReason,
    /// Training mean squared error (standardized targets) at the kept weights.
    pub train_mse: f64,
    /// Held-out mean squared error (standardized targets) at the kept weights
    /// (the training MSE when nothing is held out).
    pub validation_mse: f64,
}

/// A trained network, with its standardization and training report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FittedMlpFields")]
pub struct FittedMlp {
    features: Standardizer,
    targets: Standardizer,
    /// Layer sizes, input first: `[n_in, hidden.., n_out]`.
    sizes: Vec<usize>,
    /// The networks whose outputs are averaged, each with all its weights
    /// and biases, layer after layer: W (row-major, out x in) then b.
    members: Vec<Vec<f64>>,
    /// One report per restart; `best` indexes the one kept.
    reports: Vec<RestartReport>,
    best: usize,
}

/// What a file stores; decoding checks every shape the forward pass relies
/// on, so a decoded network predicts or errs but never indexes out of range.
#[derive(Deserialize)]
struct FittedMlpFields {
    features: Standardizer,
    targets: Standardizer,
    sizes: Vec<usize>,
    members: Vec<Vec<f64>>,
    reports: Vec<RestartReport>,
    best: usize,
}

impl TryFrom<FittedMlpFields> for FittedMlp {
    type Error = FitError;
    fn try_from(f: FittedMlpFields) -> Result<Self> {
        let shape = |what: String| Err(FitError::ShapeMismatch(format!("stored network: {what}")));
        if f.sizes.len() < 3 || f.sizes.len() > 6 {
            return shape(format!("{} layers, expected 3 to 6", f.sizes.len()));
        }
        if let Some(w) = f.sizes.iter().find(|&&w| w == 0 || w > MAX_WIDTH) {
            return shape(format!("a layer of width {w}, expected 1..={MAX_WIDTH}"));
        }
        if f.sizes[0] != f.features.dim() || f.sizes[f.sizes.len() - 1] != f.targets.dim() {
            return shape(format!(
                "layers {:?} for {} features and {} targets",
                f.sizes,
                f.features.dim(),
                f.targets.dim()
            ));
        }
        let count = parameter_count(&f.sizes);
        if f.members.is_empty() || f.members.iter().any(|m| m.len() != count) {
            return shape(format!(
                "{} member networks, each must have {count} weights",
                f.members.len()
            ));
        }
        if f.best >= f.reports.len() {
            return shape(format!(
                "best restart {} of {} reports",
                f.best,
                f.reports.len()
            ));
        }
        Ok(Self {
            features: f.features,
            targets: f.targets,
            sizes: f.sizes,
            members: f.members,
            reports: f.reports,
            best: f.best,
        })
    }
}

impl FittedMlp {
    /// The restarts' reports.
    pub fn reports(&self) -> &[RestartReport] {
        &self.reports
    }
    /// The restart whose weights were kept.
    pub fn best_restart(&self) -> &RestartReport {
        &self.reports[self.best]
    }
    /// Layer sizes, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }
    /// Number of weights and biases of one network.
    pub fn n_parameters(&self) -> usize {
        parameter_count(&self.sizes)
    }
    /// Number of networks averaged (1 unless trained as an ensemble).
    pub fn n_members(&self) -> usize {
        self.members.len()
    }
}

/// Number of parameters of a network with these layer sizes.
fn parameter_count(sizes: &[usize]) -> usize {
    sizes.windows(2).map(|w| w[1] * (w[0] + 1)).sum()
}

/// Forward pass on standardized input `x`, keeping every layer's activation
/// in `acts` (layer l starts at `offsets[l]`); returns nothing, the output
/// is the last layer.
fn forward(sizes: &[usize], params: &[f64], x: &[f64], acts: &mut [f64], offsets: &[usize]) {
    acts[..sizes[0]].copy_from_slice(x);
    let mut p = 0;
    let layers = sizes.len() - 1;
    for l in 0..layers {
        let (n_in, n_out) = (sizes[l], sizes[l + 1]);
        let (before, after) = acts.split_at_mut(offsets[l + 1]);
        let input = &before[offsets[l]..offsets[l] + n_in];
        let w = &params[p..p + n_out * n_in];
        let b = &params[p + n_out * n_in..p + n_out * (n_in + 1)];
        dense_layer(w, b, input, activation(l, layers), &mut after[..n_out]);
        p += n_out * (n_in + 1);
    }
}

/// Hidden layers are tanh, the output layer linear.
fn activation(layer: usize, layers: usize) -> Activation {
    if layer + 1 < layers {
        Activation::Tanh
    } else {
        Activation::Identity
    }
}

/// One backward step through a tanh layer: `delta_{l-1} = (W_l' delta_l)
/// .* (1 - a^2)`, with `a` the layer's input activations. `delta` holds
/// `delta_l` in its first half and receives `delta_{l-1}` there; the second
/// half is scratch, so the step never reads what it has overwritten.
fn backward(w: &[f64], input: &[f64], n_out: usize, delta: &mut [f64]) {
    let n_in = input.len();
    let (cur, next) = delta.split_at_mut(MAX_WIDTH);
    for c in 0..n_in {
        let mut acc = 0.0;
        for a in 0..n_out {
            acc += w[a * n_in + c] * cur[a];
        }
        next[c] = acc * (1.0 - input[c] * input[c]);
    }
    cur[..n_in].copy_from_slice(&next[..n_in]);
}

/// The training problem of one restart: standardized data and buffers.
struct Problem<'a> {
    sizes: &'a [usize],
    offsets: Vec<usize>,
    x: &'a Array2<f64>,
    t: &'a Array2<f64>,
    train: &'a [usize],
    held_out: &'a [usize],
    decay: f64,
}

impl Problem<'_> {
    fn n_params(&self) -> usize {
        parameter_count(self.sizes)
    }

    /// Mean squared error over `rows`, per target value.
    fn mse(&self, params: &[f64], rows: &[usize], acts: &mut [f64]) -> f64 {
        let q = *self.sizes.last().unwrap_or(&1);
        let out = self.offsets[self.sizes.len() - 1];
        let mut sse = 0.0;
        for &i in rows {
            let xi = self.x.row(i);
            let xi = xi.as_slice().unwrap_or(&[]);
            forward(self.sizes, params, xi, acts, &self.offsets);
            for k in 0..q {
                sse += (acts[out + k] - self.t[[i, k]]).powi(2);
            }
        }
        sse / (rows.len() * q).max(1) as f64
    }

    fn penalty(&self, params: &[f64]) -> f64 {
        self.decay * params.iter().map(|v| v * v).sum::<f64>()
    }

    /// Gradient of the mean squared error over `rows` (per target value)
    /// plus the weight decay term, by one backward pass per sample seeded
    /// with its residual.
    fn gradient(
        &self,
        params: &[f64],
        rows: &[usize],
        grad: &mut [f64],
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        let sizes = self.sizes;
        let layers = sizes.len() - 1;
        let q = sizes[layers];
        let out = self.offsets[layers];
        grad.fill(0.0);
        let scale = 2.0 / (rows.len() * q).max(1) as f64;
        for &i in rows {
            let xi = self.x.row(i);
            let xi = xi.as_slice().unwrap_or(&[]);
            forward(sizes, params, xi, acts, &self.offsets);
            for k in 0..q {
                delta[k] = scale * (acts[out + k] - self.t[[i, k]]);
            }
            let mut s = params.len();
            for l in (0..layers).rev() {
                let (n_in, n_out) = (sizes[l], sizes[l + 1]);
                s -= n_out * (n_in + 1);
                let input = &acts[self.offsets[l]..self.offsets[l] + n_in];
                for a in 0..n_out {
                    let d = delta[a];
                    for (c, inp) in input.iter().enumerate() {
                        grad[s + a * n_in + c] += d * inp;
                    }
                    grad[s + n_out * n_in + a] += d;
                }
                if l > 0 {
                    backward(&params[s..s + n_out * n_in], input, n_out, delta);
                }
            }
        }
        let decay = 2.0 * self.decay / (self.train.len() * q).max(1) as f64;
        for (g, p) in grad.iter_mut().zip(params) {
            *g += decay * p;
        }
    }

    /// Residuals r (train rows x targets) and their Jacobian J.
    fn jacobian(
        &self,
        params: &[f64],
        jac: &mut Mat<f64>,
        res: &mut Mat<f64>,
        acts: &mut [f64],
        delta: &mut [f64],
    ) {
        let sizes = self.sizes;
        let layers = sizes.len() - 1;
        let q = sizes[layers];
        let out = self.offsets[layers];
        // Start of each layer's parameters.
        let mut starts = Vec::with_capacity(layers);
        let mut p = 0;
        for l in 0..layers {
            starts.push(p);
            p += sizes[l + 1] * (sizes[l] + 1);
        }
        for (row_block, &i) in self.train.iter().enumerate() {
            let xi = self.x.row(i);
            let xi = xi.as_slice().unwrap_or(&[]);
            forward(sizes, params, xi, acts, &self.offsets);
            for k in 0..q {
                let r = row_block * q + k;
                res[(r, 0)] = acts[out + k] - self.t[[i, k]];
                // Back-propagate the unit seed of output k.
                delta[..q].fill(0.0);
                delta[k] = 1.0;
                for l in (0..layers).rev() {
                    let (n_in, n_out) = (sizes[l], sizes[l + 1]);
                    let input = &acts[self.offsets[l]..self.offsets[l] + n_in];
                    let s = starts[l];
                    for a in 0..n_out {
                        let d = delta[a];
                        for (c, inp) in input.iter().enumerate() {
                            jac[(r, s + a * n_in + c)] = d * inp;
                        }
                        jac[(r, s + n_out * n_in + a)] = d;
                    }
                    if l > 0 {
                        backward(&params[s..s + n_out * n_in], input, n_out, delta);
                    }
                }
            }
        }
    }
}

/// Glorot-uniform weights, small random biases.
fn initial_parameters(sizes: &[usize], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut params = Vec::with_capacity(parameter_count(sizes));
    for w in sizes.windows(2) {
        let (n_in, n_out) = (w[0], w[1]);
        let limit = (6.0 / (n_in + n_out) as f64).sqrt();
        params.extend((0..n_out * n_in).map(|_| rng.random_range(-limit..limit)));
        params.extend((0..n_out).map(|_| rng.random_range(-0.5..0.5)));
    }
    params
}

/// Keeps the weights with the lowest held-out loss and says when `patience`
/// checks have passed without improvement (never, when nothing is held out).
struct BestHeldOut {
    loss: f64,
    params: Vec<f64>,
    since: usize,
    patience: usize,
    active: bool,
}

impl BestHeldOut {
    fn new(loss: f64, params: &[f64], patience: usize, active: bool) -> Self {
        Self {
            loss,
            params: params.to_vec(),
            since: 0,
            patience,
            active,
        }
    }

    /// Record the held-out loss of `params`; true when training should stop.
    fn observe(&mut self, loss: f64, params: &[f64]) -> bool {
        if loss < self.loss {
            self.loss = loss;
            self.params.copy_from_slice(params);
            self.since = 0;
            false
        } else {
            self.since += 1;
            self.active && self.since >= self.patience
        }
    }
}

/// Whether Levenberg-Marquardt is used for this problem size.
fn use_levenberg_marquardt(trainer: Trainer, rows: usize, n_params: usize) -> bool {
    match trainer {
        Trainer::LevenbergMarquardt => true,
        Trainer::Adam { .. } => false,
        Trainer::Auto => n_params <= 1000 && rows.saturating_mul(n_params) <= 20_000_000,
    }
}

fn train_one(problem: &Problem<'_>, mlp: &MlpParams, restart: usize) -> (Vec<f64>, RestartReport) {
    let mut rng = ChaCha8Rng::seed_from_u64(mlp.seed ^ 0x4d4c_5000);
    rng.set_stream(restart as u64 + 1);
    let params = initial_parameters(problem.sizes, &mut rng);
    let q = *problem.sizes.last().unwrap_or(&1);
    if use_levenberg_marquardt(mlp.trainer, problem.train.len() * q, problem.n_params()) {
        train_levenberg_marquardt(problem, mlp, restart, params)
    } else {
        let (learning_rate, batch_size, epochs) = match mlp.trainer {
            Trainer::Adam {
                learning_rate,
                batch_size,
                epochs,
            } => (learning_rate, batch_size, epochs),
            _ => (1e-3, 64, 500),
        };
        train_adam(
            problem,
            mlp,
            restart,
            params,
            &mut rng,
            (learning_rate, batch_size, epochs),
        )
    }
}

/// Adam on shuffled mini-batches, keeping the weights of the best held-out
/// epoch; `patience` counts epochs.
fn train_adam(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    mut params: Vec<f64>,
    rng: &mut ChaCha8Rng,
    (learning_rate, batch_size, epochs): (f64, usize, usize),
) -> (Vec<f64>, RestartReport) {
    const BETA1: f64 = 0.9;
    const BETA2: f64 = 0.999;
    const EPSILON: f64 = 1e-8;
    let n = problem.n_params();
    let width = problem.offsets.last().copied().unwrap_or(0);
    let mut acts = vec![0.0; width];
    let mut delta = vec![0.0; 2 * MAX_WIDTH];
    let (mut grad, mut m, mut v) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let held_out = if problem.held_out.is_empty() {
        problem.train
    } else {
        problem.held_out
    };
    let mut order = problem.train.to_vec();
    let initial = problem.mse(&params, held_out, &mut acts);
    let mut best = BestHeldOut::new(initial, &params, mlp.patience, !problem.held_out.is_empty());
    let (mut step, mut done) = (0i32, 0);
    let mut reason = TerminationReason::MaxEpochs;
    for _ in 0..epochs {
        done += 1;
        order.shuffle(rng);
        for batch in order.chunks(batch_size) {
            problem.gradient(&params, batch, &mut grad, &mut acts, &mut delta);
            step += 1;
            let (c1, c2) = (1.0 - BETA1.powi(step), 1.0 - BETA2.powi(step));
            for j in 0..n {
                m[j] = BETA1 * m[j] + (1.0 - BETA1) * grad[j];
                v[j] = BETA2 * v[j] + (1.0 - BETA2) * grad[j] * grad[j];
                params[j] -= learning_rate * (m[j] / c1) / ((v[j] / c2).sqrt() + EPSILON);
            }
        }
        let held = problem.mse(&params, held_out, &mut acts);
        if best.observe(held, &params) {
            reason = TerminationReason::EarlyStopping;
            break;
        }
    }
    let (validation_mse, kept) = (best.loss, best.params);
    let report = RestartReport {
        restart,
        iterations: done,
        reason,
        train_mse: problem.mse(&kept, problem.train, &mut acts),
        validation_mse,
    };
    (kept, report)
}

fn train_levenberg_marquardt(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    params: Vec<f64>,
) -> (Vec<f64>, RestartReport) {
    let held_out = if problem.held_out.is_empty() {
        problem.train
    } else {
        problem.held_out
    };
    let width = problem.offsets.last().copied().unwrap_or(0);
    let mut acts = vec![0.0; width];
    let initial = problem.mse(&params, held_out, &mut acts);
    let mut best = BestHeldOut::new(initial, &params, mlp.patience, !problem.held_out.is_empty());
    let mut least_squares = NetworkLeastSquares::new(problem);
    let solver = LevenbergMarquardt::new()
        .max_iterations(mlp.max_iterations)
        .tolerance(1e-12)
        .damping(Damping::Identity)
        .initial_damping(1e-3)
        .max_damping(1e10);
    let Ok(minimum) = solver.minimize(&mut least_squares, &params, |iterate| {
        let held = problem.mse(iterate.x, held_out, &mut acts);
        if best.observe(held, iterate.x) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    let (validation_mse, kept) = (best.loss, best.params);
    let report = RestartReport {
        restart,
        iterations: minimum.iterations,
        reason: minimum.reason,
        train_mse: problem.mse(&kept, problem.train, &mut acts),
        validation_mse,
    };
    (kept, report)
}

/// The training rows' residuals as a least-squares problem: the cost is
/// the mean squared error per target value plus the weight decay over the
/// same count, and the Gauss-Newton products come from the back-propagated
/// Jacobian (kept here between iterations: rows x parameters).
struct NetworkLeastSquares<'p, 'a> {
    problem: &'p Problem<'a>,
    rows: usize,
    acts: Vec<f64>,
    delta: Vec<f64>,
    jac: Mat<f64>,
    res: Mat<f64>,
    jtj: Mat<f64>,
    jtr: Mat<f64>,
}

impl<'p, 'a> NetworkLeastSquares<'p, 'a> {
    fn new(problem: &'p Problem<'a>) -> Self {
        let n = problem.n_params();
        let q = *problem.sizes.last().unwrap_or(&1);
        let rows = problem.train.len() * q;
        Self {
            problem,
            rows,
            acts: vec![0.0; problem.offsets.last().copied().unwrap_or(0)],
            delta: vec![0.0; 2 * MAX_WIDTH],
            jac: Mat::zeros(rows, n),
            res: Mat::zeros(rows, 1),
            jtj: Mat::zeros(n, n),
            jtr: Mat::zeros(n, 1),
        }
    }
}

impl LeastSquaresProblem for NetworkLeastSquares<'_, '_> {
    type Error = std::convert::Infallible;

    fn residuals(
        &mut self,
        params: &[f64],
        r: &mut Vec<f64>,
    ) -> std::result::Result<(), Self::Error> {
        let problem = self.problem;
        let q = *problem.sizes.last().unwrap_or(&1);
        let out = problem.offsets[problem.sizes.len() - 1];
        r.clear();
        for &i in problem.train {
            let xi = problem.x.row(i);
            forward(
                problem.sizes,
                params,
                xi.as_slice().unwrap_or(&[]),
                &mut self.acts,
                &problem.offsets,
            );
            r.extend((0..q).map(|k| self.acts[out + k] - problem.t[[i, k]]));
        }
        Ok(())
    }

    fn cost(&mut self, params: &[f64], r: &[f64]) -> f64 {
        let sse: f64 = r.iter().map(|v| v * v).sum();
        sse / self.rows.max(1) as f64 + self.problem.penalty(params) / (self.rows as f64)
    }

    fn gauss_newton(
        &mut self,
        params: &[f64],
        _r: &[f64],
        jtj: &mut [f64],
        jtr: &mut [f64],
    ) -> std::result::Result<(), Self::Error> {
        let n = jtr.len();
        let scale = 1.0 / self.rows as f64;
        self.problem.jacobian(
            params,
            &mut self.jac,
            &mut self.res,
            &mut self.acts,
            &mut self.delta,
        );
        matmul(
            self.jtj.as_mut(),
            Accum::Replace,
            self.jac.transpose(),
            self.jac.as_ref(),
            scale,
            Par::Seq,
        );
        matmul(
            self.jtr.as_mut(),
            Accum::Replace,
            self.jac.transpose(),
            self.res.as_ref(),
            scale,
            Par::Seq,
        );
        // The weight decay term decay * ||p||^2 / rows: its Hessian and gradient.
        let d = self.problem.decay * scale;
        for i in 0..n {
            for j in 0..=i {
                jtj[i * n + j] = self.jtj[(i, j)];
            }
            jtj[i * n + i] += d;
            jtr[i] = self.jtr[(i, 0)] + d * params[i];
        }
        Ok(())
    }
}

impl Regressor for Mlp {
    type Model = FittedMlp;

    fn fit(&self, x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<FittedMlp> {
        check::training_data(x, y)?;
        let p = &self.params;
        let (m, n_in) = x.dim();
        let q = y.ncols();
        if n_in > MAX_WIDTH || q > MAX_WIDTH {
            return Err(FitError::InvalidSetting {
                name: "features or targets",
                value: format!("{n_in} features, {q} targets"),
                reason: "at most 256 each".into(),
            });
        }
        let mut sizes = vec![n_in];
        sizes.extend(&p.hidden);
        sizes.push(q);
        let n_params = parameter_count(&sizes);
        let n_held = (p.validation_fraction * m as f64).round() as usize;
        let n_train = m - n_held;
        if n_train < 2 || (p.validation_fraction > 0.0 && n_held == 0) {
            return Err(FitError::TooFewSamples {
                got: m,
                needed: 2 + usize::from(p.validation_fraction > 0.0),
                why: "training and held-out sets both need samples".into(),
            });
        }
        let features = Standardizer::fit(x);
        let targets = Standardizer::fit(y);
        // Standard layout so rows are contiguous slices.
        let xs = features.transform(x).as_standard_layout().to_owned();
        let ts = targets.transform(y);
        let mut order: Vec<usize> = (0..m).collect();
        let mut split_rng = ChaCha8Rng::seed_from_u64(p.seed ^ 0x5350_4c49_5400);
        order.shuffle(&mut split_rng);
        let (held_out, train) = order.split_at(n_held);
        let mut offsets = vec![0];
        for s in &sizes {
            offsets.push(offsets.last().copied().unwrap_or(0) + s);
        }
        let problem = Problem {
            sizes: &sizes,
            offsets,
            x: &xs,
            t: &ts,
            train,
            held_out,
            decay: p.weight_decay,
        };
        let _ = n_params;
        let runs: Vec<(Vec<f64>, RestartReport)> = (0..p.restarts)
            .into_par_iter()
            .map(|r| train_one(&problem, p, r))
            .collect();
        // The lowest held-out loss wins; ties go to the lower index, so the
        // choice does not depend on scheduling.
        let best = runs
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.1.validation_mse.total_cmp(&b.1.1.validation_mse))
            .map(|(i, _)| i)
            .unwrap_or(0);
        let (members, reports): (Vec<Vec<f64>>, Vec<RestartReport>) = runs.into_iter().unzip();
        let members = if p.ensemble {
            members
        } else {
            vec![members[best].clone()]
        };
        Ok(FittedMlp {
            features,
            targets,
            sizes,
            members,
            reports,
            best,
        })
    }
}

impl Predictor for FittedMlp {
    fn n_inputs(&self) -> usize {
        self.sizes[0]
    }

    fn n_outputs(&self) -> usize {
        *self.sizes.last().unwrap_or(&0)
    }

    fn predict_into(&self, x: &[f64], out: &mut [f64]) -> Result<()> {
        let q = self.n_outputs();
        check::row_lengths(x, out, self.n_inputs(), q)?;
        let mut input = [0.0f64; MAX_WIDTH];
        self.features.transform_into(x, &mut input[..self.sizes[0]]);
        out.fill(0.0);
        for params in &self.members {
            // Two stack buffers, used in turn as input and output of each layer.
            let mut a = input;
            let mut b = [0.0f64; MAX_WIDTH];
            let layers = self.sizes.len() - 1;
            let mut p = 0;
            for l in 0..layers {
                let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
                let w = &params[p..p + n_out * n_in];
                let bias = &params[p + n_out * n_in..p + n_out * (n_in + 1)];
                dense_layer(w, bias, &a[..n_in], activation(l, layers), &mut b[..n_out]);
                std::mem::swap(&mut a, &mut b);
                p += n_out * (n_in + 1);
            }
            for (o, v) in out.iter_mut().zip(&a[..q]) {
                *o += v;
            }
        }
        let members = self.members.len() as f64;
        for o in out.iter_mut() {
            *o /= members;
        }
        self.targets.inverse_in_place(out);
        Ok(())
    }
}

/// The network's outputs and their Jacobian with respect to all parameters
/// at one (standardized) input: for tests of back-propagation.
#[doc(hidden)]
pub fn jacobian_at(sizes: &[usize], params: &[f64], x: &[f64]) -> (Vec<f64>, Array2<f64>) {
    let mut offsets = vec![0];
    for s in sizes {
        offsets.push(offsets.last().copied().unwrap_or(0) + s);
    }
    let q = *sizes.last().unwrap_or(&1);
    let xs = Array2::from_shape_vec((1, x.len()), x.to_vec()).unwrap_or_default();
    let ts = Array2::zeros((1, q));
    let train = [0usize];
    let problem = Problem {
        sizes,
        offsets: offsets.clone(),
        x: &xs,
        t: &ts,
        train: &train,
        held_out: &[],
        decay: 0.0,
    };
    let n = parameter_count(sizes);
    let mut jac = Mat::zeros(q, n);
    let mut res = Mat::zeros(q, 1);
    let mut acts = vec![0.0; offsets.last().copied().unwrap_or(0)];
    let mut delta = vec![0.0; 2 * MAX_WIDTH];
    problem.jacobian(params, &mut jac, &mut res, &mut acts, &mut delta);
    let outputs = (0..q).map(|k| res[(k, 0)]).collect();
    (outputs, Array2::from_shape_fn((q, n), |(i, j)| jac[(i, j)]))
}

/// The training loss (mean squared error per target value plus weight
/// decay over the sample count) and its gradient, on standardized data:
/// for tests of the Adam gradient.
#[doc(hidden)]
pub fn loss_gradient_at(
    sizes: &[usize],
    params: &[f64],
    x: &Array2<f64>,
    t: &Array2<f64>,
    decay: f64,
) -> (f64, Vec<f64>) {
    let mut offsets = vec![0];
    for s in sizes {
        offsets.push(offsets.last().copied().unwrap_or(0) + s);
    }
    let rows: Vec<usize> = (0..x.nrows()).collect();
    let x = x.as_standard_layout().to_owned();
    let problem = Problem {
        sizes,
        offsets: offsets.clone(),
        x: &x,
        t,
        train: &rows,
        held_out: &[],
        decay,
    };
    let q = *sizes.last().unwrap_or(&1);
    let mut acts = vec![0.0; offsets.last().copied().unwrap_or(0)];
    let mut delta = vec![0.0; 2 * MAX_WIDTH];
    let mut grad = vec![0.0; params.len()];
    problem.gradient(params, &rows, &mut grad, &mut acts, &mut delta);
    let loss =
        problem.mse(params, &rows, &mut acts) + problem.penalty(params) / (rows.len() * q) as f64;
    (loss, grad)
}

/// Parameter count for layer sizes `[n_in, hidden.., n_out]`.
#[doc(hidden)]
pub fn n_parameters(sizes: &[usize]) -> usize {
    parameter_count(sizes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_picks_levenberg_marquardt_for_small_problems_only() {
        assert!(use_levenberg_marquardt(Trainer::Auto, 3000, 222));
        assert!(!use_levenberg_marquardt(Trainer::Auto, 200_000, 222));
        assert!(!use_levenberg_marquardt(Trainer::Auto, 100, 5000));
        assert!(use_levenberg_marquardt(
            Trainer::LevenbergMarquardt,
            200_000,
            5000
        ));
        assert!(!use_levenberg_marquardt(Trainer::ADAM, 10, 10));
    }
}
