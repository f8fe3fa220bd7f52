//! A conditional density of the parameters given the features: a tanh
//! network whose output layer parameterizes a mixture of Gaussians with
//! full covariances ([`twostage_kernels::mixture`]) over the parameters
//! mapped to the whole real line, trained by the negative log-likelihood
//! of the chart's parameters (Bishop, "Mixture density networks", 1994).
//!
//! The network, its restarts, its held-out stopping and its deadline are
//! the regression network's ([`MlpParams`]); the loss is not a sum of
//! squares, so every restart runs L-BFGS on the whole training set (the
//! regression network's, [`super::lbfgs::minimize`]). Blocks of rows and
//! the order their sums are added in are fixed: the same bits on any
//! thread count.

use ndarray::{Array2, ArrayView2};
use rand::Rng;
use serde::{Deserialize, Serialize};
use twostage_kernels::mixture::{MixtureShape, Support, log_sum_exp};

use crate::error::{FitError, InvalidSetting, Result};
use crate::standardize::Standardizer;

use super::likelihood::{DensityRestart, Head, fit_network, head_of};
use super::network::{MAX_WIDTH, parameter_count};
use super::params::{Mlp, MlpParams};
use super::stored::{stored_best, stored_layers};

/// How a mixture density network learns: the network (its hidden layers,
/// restarts, held-out fraction, patience, weight decay, seed and
/// deadline), the mixture's components, and the L-BFGS iterations of each
/// restart (the density's own: the held-out loss usually stops a restart
/// well before them).
///
/// ```
/// use ndarray::Array2;
/// use rand::SeedableRng;
/// use twostage_fit::{MixtureDensity, MlpParams, Support};
/// // theta = 2 x + noise of sd 0.1: the density at x = 0.25 centres on 0.5.
/// let x = Array2::from_shape_fn((400, 1), |(i, _)| (i as f64 / 399.0) - 0.5);
/// let theta = Array2::from_shape_fn((400, 1), |(i, _)| {
///     2.0 * x[[i, 0]] + 0.1 * ((i * 7919 % 400) as f64 / 400.0 - 0.5) * 12f64.sqrt()
/// });
/// let network = MlpParams::new(&[8])?.restarts(2).seed(1).check()?;
/// let density = MixtureDensity::new(network, 1)?.fit(x.view(), theta.view(), &[Support::Real])?;
/// let mut draws = vec![0.0; 2000];
/// density.sample(&[0.25], &mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &mut draws)?;
/// let mean = draws.iter().sum::<f64>() / 2000.0;
/// assert!((mean - 0.5).abs() < 0.03, "{mean}");
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
#[derive(Debug, Clone)]
pub struct MixtureDensity {
    network: MlpParams,
    components: usize,
    iterations: usize,
    /// Whether `components` is the most of several counts tried.
    choose: bool,
    /// When the whole fit must end, the counts tried sharing the time.
    stop_by: Option<std::time::Instant>,
}

/// A trained mixture density network: `p(θ | features)`, to evaluate and
/// draw from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "FittedMixtureFields")]
pub struct FittedMixture {
    features: Standardizer,
    /// The standardization of the parameters mapped to the real line.
    unbounded: Standardizer,
    supports: Vec<Support>,
    shape: MixtureShape,
    /// Layer sizes, input first; the last is the head's length.
    sizes: Vec<usize>,
    /// All weights and biases, layer after layer: W (row-major, out x
    /// in) then b.
    params: Vec<f64>,
    reports: Vec<DensityRestart>,
    best: usize,
    /// The factor every component's spread is widened by, calibrated on
    /// records the network did not see (1 before).
    spread: f64,
}

/// What a file stores; decoding checks every shape the head and the
/// draws rely on, so a decoded density evaluates or errs but never indexes
/// out of range.
#[derive(Deserialize)]
struct FittedMixtureFields {
    features: Standardizer,
    unbounded: Standardizer,
    supports: Vec<Support>,
    shape: MixtureShape,
    sizes: Vec<usize>,
    params: Vec<f64>,
    reports: Vec<DensityRestart>,
    best: usize,
    spread: f64,
}

impl TryFrom<FittedMixtureFields> for FittedMixture {
    type Error = FitError;
    fn try_from(f: FittedMixtureFields) -> Result<Self> {
        let shape = |what: String| Err(FitError::ShapeMismatch(format!("stored density: {what}")));
        let dim = f.shape.dim;
        if f.shape.components == 0 || dim == 0 || f.shape.outputs() > MAX_WIDTH {
            return shape(format!(
                "{} components of {dim} parameters",
                f.shape.components
            ));
        }
        stored_layers(&f.sizes, f.features.dim(), f.shape.outputs())?;
        if f.params.len() != parameter_count(&f.sizes) {
            return shape(format!(
                "{} weights for layers {:?}",
                f.params.len(),
                f.sizes
            ));
        }
        if f.unbounded.dim() != dim || f.supports.len() != dim {
            return shape(format!(
                "{} standardized parameters and {} supports for {dim} parameters",
                f.unbounded.dim(),
                f.supports.len()
            ));
        }
        if let Some(bad) = f.supports.iter().find(|s| match s {
            Support::Interval { low, high } => !(low.is_finite() && high.is_finite() && low < high),
            _ => false,
        }) {
            return shape(format!("the support {bad:?}"));
        }
        stored_best(f.best, f.reports.len())?;
        if !(f.spread.is_finite() && f.spread > 0.0) {
            return shape(format!("a spread of {}", f.spread));
        }
        Ok(Self {
            features: f.features,
            unbounded: f.unbounded,
            supports: f.supports,
            shape: f.shape,
            sizes: f.sizes,
            params: f.params,
            reports: f.reports,
            best: f.best,
            spread: f.spread,
        })
    }
}

impl MixtureDensity {
    /// L-BFGS iterations a restart unless set otherwise: a density's
    /// likelihood is not a sum of squares, so its descent takes many more
    /// of them than the regression network's Levenberg-Marquardt.
    pub const DEFAULT_ITERATIONS: usize = 5000;

    /// A mixture of `components` Gaussians given by `network`.
    ///
    /// # Errors
    /// No component, or an ensemble asked of the network (a density is
    /// one network).
    pub fn new(network: Mlp, components: usize) -> Result<Self> {
        let network = network.params().clone();
        if components == 0 {
            return Err(invalid("components", "0".into(), "at least 1"));
        }
        if network.ensemble {
            return Err(invalid(
                "ensemble",
                "true".into(),
                "a mixture density is one network: leave the ensemble out",
            ));
        }
        Ok(Self {
            network,
            components,
            iterations: Self::DEFAULT_ITERATIONS,
            choose: false,
            stop_by: None,
        })
    }

    /// Hidden layers of a density given by its components alone.
    pub const DEFAULT_HIDDEN: [usize; 2] = [32, 32];

    /// A mixture of `components` Gaussians on the default network
    /// ([`Self::DEFAULT_HIDDEN`] tanh units, the regression network's
    /// restarts, held-out fraction, patience and weight decay): what a
    /// door asks for when it names only the components.
    ///
    /// # Errors
    /// No component.
    pub fn with_components(components: usize) -> Result<Self> {
        Self::new(MlpParams::new(&Self::DEFAULT_HIDDEN)?.check()?, components)
    }

    /// At most `iterations` L-BFGS iterations a restart (default
    /// [`Self::DEFAULT_ITERATIONS`]).
    ///
    /// # Errors
    /// None asked.
    pub fn iterations(mut self, iterations: usize) -> Result<Self> {
        if iterations == 0 {
            return Err(invalid("iterations", "0".into(), "at least 1"));
        }
        self.iterations = iterations;
        Ok(self)
    }

    /// Component counts a choosing density tries, up to its components.
    pub const CANDIDATE_COMPONENTS: [usize; 5] = [1, 2, 3, 5, 8];

    /// The same density, its components the most of the counts tried:
    /// each of [`Self::CANDIDATE_COMPONENTS`] up to them (and them) is
    /// fitted on the same rows, and the one of the lowest held-out
    /// negative log-likelihood kept (the fewer components on a tie).
    pub fn choosing_components(mut self) -> Self {
        self.choose = true;
        self
    }

    /// The same density, its fit ended at `stop_by` if it has not ended
    /// by then: each count tried gets an equal share of the time left
    /// when it starts (what an earlier one leaves goes to the later
    /// ones), and each restart keeps its best held-out weights so far
    /// ([`super::params::Mlp::stopped_by`]). For a density within a time
    /// budget; [`FittedMixture::stopped_at_deadline`] says whether it was
    /// cut short.
    pub fn stopped_by(mut self, stop_by: std::time::Instant) -> Self {
        self.stop_by = Some(stop_by);
        self
    }

    /// The component counts `fit` tries.
    pub fn candidates(&self) -> Vec<usize> {
        if !self.choose {
            return vec![self.components];
        }
        let mut counts: Vec<usize> = Self::CANDIDATE_COMPONENTS
            .into_iter()
            .filter(|&k| k < self.components)
            .collect();
        counts.push(self.components);
        counts
    }

    /// The same density seeded by `seed` (its restarts' weights and its
    /// held-out rows).
    pub fn seeded(&self, seed: u64) -> Self {
        let mut seeded = self.clone();
        seeded.network.seed = seed;
        seeded
    }

    /// The density of `theta` (rows x parameters) given `x` (rows x
    /// features), each parameter on its `supports` entry; where it
    /// chooses its components ([`Self::choosing_components`]), the count
    /// of the lowest held-out negative log-likelihood.
    ///
    /// # Errors
    /// Shapes that do not match, non-finite values, a parameter outside
    /// its support (its row and column named), too few rows, or a head
    /// wider than the network allows.
    pub fn fit(
        &self,
        x: ArrayView2<'_, f64>,
        theta: ArrayView2<'_, f64>,
        supports: &[Support],
    ) -> Result<FittedMixture> {
        let mut best: Option<FittedMixture> = None;
        let candidates = self.candidates();
        for (k, &components) in candidates.iter().enumerate() {
            let mut network = self.network.clone();
            if let Some(end) = self.stop_by {
                let now = std::time::Instant::now();
                let share = end.saturating_duration_since(now) / (candidates.len() - k) as u32;
                network.stop_by = Some(now + share);
            }
            let fitted = self.fit_components(&network, components, x, theta, supports)?;
            let better = best
                .as_ref()
                .is_none_or(|b| fitted.best_restart().held_out_nll < b.best_restart().held_out_nll);
            if better {
                best = Some(fitted);
            }
        }
        best.ok_or_else(|| invalid("components", "none".into(), "at least 1"))
    }

    /// The density of `components` components, fitted.
    fn fit_components(
        &self,
        p: &MlpParams,
        components: usize,
        x: ArrayView2<'_, f64>,
        theta: ArrayView2<'_, f64>,
        supports: &[Support],
    ) -> Result<FittedMixture> {
        crate::check::training_data(x, theta)?;
        let (m, n_in) = x.dim();
        let dim = theta.ncols();
        if supports.len() != dim {
            return Err(FitError::ShapeMismatch(format!(
                "{} supports for {dim} parameters",
                supports.len()
            )));
        }
        let shape = MixtureShape { components, dim };
        if n_in > MAX_WIDTH || shape.outputs() > MAX_WIDTH {
            return Err(invalid(
                "components",
                format!(
                    "{components} components of {dim} parameters ({} outputs), {n_in} features",
                    shape.outputs()
                ),
                "at most 256 features and outputs: fewer components",
            ));
        }
        let mut z = Array2::zeros((m, dim));
        for ((i, j), &v) in theta.indexed_iter() {
            if !inside(supports[j], v) {
                return Err(invalid(
                    "parameter values",
                    format!("row {i}, parameter {j}: {v}"),
                    &format!("outside its support {:?}", supports[j]),
                ));
            }
            z[[i, j]] = supports[j].to_unbounded(v);
        }
        let features = Standardizer::fit(x);
        let unbounded = Standardizer::fit(z.view());
        let xs = features.transform(x).as_standard_layout().to_owned();
        let zs = unbounded
            .transform(z.view())
            .as_standard_layout()
            .to_owned();
        let (sizes, params, reports, best) =
            fit_network(shape, shape.outputs(), (&xs, &zs), p, self.iterations)?;
        Ok(FittedMixture {
            features,
            unbounded,
            supports: supports.to_vec(),
            shape,
            sizes,
            params,
            reports,
            best,
            spread: 1.0,
        })
    }
}

fn invalid(name: &'static str, value: String, reason: &str) -> FitError {
    FitError::InvalidSetting(InvalidSetting {
        name,
        value,
        reason: reason.into(),
    })
}

/// Whether `value` lies in `support` (bounds included).
fn inside(support: Support, value: f64) -> bool {
    match support {
        Support::Real => value.is_finite(),
        Support::Positive => value > 0.0 && value.is_finite(),
        Support::Interval { low, high } => (low..=high).contains(&value),
    }
}

/// Every component of `head` widened by `spread`: its covariance times
/// `spread²`, so its precision factor over `spread` (the log-diagonal less
/// `log spread`, the entries above it divided by it).
fn widen(shape: MixtureShape, head: &mut [f64], spread: f64) {
    // A spread of 1 changes no bit: x - 0 and x / 1 are x.
    shape.widen(head, spread, spread.ln());
}

impl Head for MixtureShape {
    fn nll(&self, head: &[f64], target: &[f64]) -> f64 {
        -self.log_density(head, target)
    }

    fn gradient(&self, head: &[f64], target: &[f64], scale: f64, delta: &mut [f64]) {
        head_gradient(*self, head, target, scale, delta);
    }
}

/// `scale` times the derivative of `−log p(z)` by each of the head's
/// entries, into `delta`'s first `shape.outputs()` entries.
///
/// With `L_c` component c's weighted log density, `r_c` its share of the
/// density at z (`softmax(L)`), `π` the weights (`softmax` of the logits),
/// `e = z − μ_c` and `y = U_c e`: by logit c, `π_c − r_c`; by `μ_c`,
/// `−r_c U_c' y`; by `log U_c,ii`, `−r_c (1 − y_i U_c,ii e_i)`; by `U_c,ij`
/// above the diagonal, `r_c y_i e_j`.
fn head_gradient(shape: MixtureShape, head: &[f64], z: &[f64], scale: f64, delta: &mut [f64]) {
    let (k, d) = (shape.components, shape.dim);
    let mut weighted = [0.0f64; MAX_WIDTH];
    for (c, w) in weighted[..k].iter_mut().enumerate() {
        *w = head[c] + shape.component_log_density(head, c, z);
    }
    let total = log_sum_exp(weighted[..k].iter().copied());
    let normalizer = shape.log_normalizer(head);
    delta[..shape.outputs()].fill(0.0);
    let mut e = [0.0f64; MAX_WIDTH];
    for c in 0..k {
        let share = (weighted[c] - total).exp();
        delta[c] = scale * ((head[c] - normalizer).exp() - share);
        let mean = shape.mean_at(c);
        let log_diagonal = shape.log_diagonal_at(c);
        let upper = shape.upper_at(c);
        for j in 0..d {
            e[j] = z[j] - head[mean + j];
        }
        for i in 0..d {
            let diagonal = head[log_diagonal + i].exp();
            let mut y = diagonal * e[i];
            for j in i + 1..d {
                y += head[upper + shape.upper_index(i, j)] * e[j];
            }
            // U' y, column by column: U_ii y_i to mean i, U_ij y_i to mean j.
            delta[mean + i] -= scale * share * diagonal * y;
            delta[log_diagonal + i] = -scale * share * (1.0 - y * diagonal * e[i]);
            for j in i + 1..d {
                let u = upper + shape.upper_index(i, j);
                delta[mean + j] -= scale * share * head[u] * y;
                delta[u] = scale * share * y * e[j];
            }
        }
    }
}

impl FittedMixture {
    /// The mixture's layout.
    pub fn shape(&self) -> MixtureShape {
        self.shape
    }

    /// The features it reads.
    pub fn n_features(&self) -> usize {
        self.sizes[0]
    }

    /// Each parameter's support.
    pub fn supports(&self) -> &[Support] {
        &self.supports
    }

    /// The standardization of the features the network reads.
    pub fn feature_scaling(&self) -> &Standardizer {
        &self.features
    }

    /// The standardization of the parameters mapped to the real line
    /// (the space the mixture lives in).
    pub fn unbounded_scaling(&self) -> &Standardizer {
        &self.unbounded
    }

    /// The network's layer sizes (features first, the head's length
    /// last) and its weights and biases, layer after layer (row-major
    /// weights, out x in, then biases): what an exporter writes.
    pub fn network(&self) -> (&[usize], &[f64]) {
        (&self.sizes, &self.params)
    }

    /// One report per restart.
    pub fn reports(&self) -> &[DensityRestart] {
        &self.reports
    }

    /// Whether a deadline ([`MixtureDensity::stopped_by`]) cut its kept
    /// restart short: it would fit better given more time.
    pub fn stopped_at_deadline(&self) -> bool {
        self.best_restart().reason.is_deadline()
    }

    /// What the density is and how it was trained, in one line: its
    /// components, layers and weights, and the kept restart's held-out
    /// negative log-likelihood (per record, standardized unbounded
    /// parameters) and iterations.
    pub fn summary(&self) -> String {
        let best = self.best_restart();
        format!(
            "mixture of {} full-covariance Gaussians over {} parameters; layers {:?}, {} \
             weights; best of {} restarts (held-out NLL {:.4}, {} L-BFGS iterations, {}); \
             spread x{:.3}",
            self.shape.components,
            self.shape.dim,
            self.sizes,
            self.params.len(),
            self.reports.len(),
            best.held_out_nll,
            best.iterations,
            best.reason.name(),
            self.spread
        )
    }

    /// The restart kept: the lowest held-out negative log-likelihood.
    pub fn best_restart(&self) -> &DensityRestart {
        &self.reports[self.best]
    }

    /// The head (the mixture over standardized unbounded parameters) of
    /// the features `x`.
    fn head(&self, x: &[f64]) -> Result<[f64; MAX_WIDTH]> {
        let mut head = head_of(
            &self.features,
            (&self.sizes, &self.params),
            x,
            "the density",
        )?;
        widen(self.shape, &mut head, self.spread);
        Ok(head)
    }

    /// The factor every component's spread is widened by
    /// ([`Self::calibrate_spread`]; 1 before).
    pub fn spread(&self) -> f64 {
        self.spread
    }

    /// Widen (or narrow) every component's spread by the factor that
    /// gives `theta` (rows x parameters) the least mean negative
    /// log-likelihood given `x`: records the network did not see, so that
    /// a density fitted on few records is not surer than they bear out.
    /// The factor is searched by golden sections of its logarithm within
    /// `[1/2, 4]`; it is the one place the density learns from these
    /// records.
    ///
    /// # Errors
    /// As [`Self::mean_nll`].
    pub fn calibrate_spread(
        &mut self,
        x: ArrayView2<'_, f64>,
        theta: ArrayView2<'_, f64>,
    ) -> Result<f64> {
        let mut at = |log_spread: f64| -> Result<f64> {
            self.spread = log_spread.exp();
            self.mean_nll(x, theta)
        };
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        let (mut a, mut b) = (0.5f64.ln(), 4f64.ln());
        let mut c = b - ratio * (b - a);
        let mut d = a + ratio * (b - a);
        let (mut fc, mut fd) = (at(c)?, at(d)?);
        // Each section keeps 0.618 of the bracket: 40 take it below 1e-8
        // of its width.
        for _ in 0..40 {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - ratio * (b - a);
                fc = at(c)?;
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + ratio * (b - a);
                fd = at(d)?;
            }
        }
        self.spread = (0.5 * (a + b)).exp();
        Ok(self.spread)
    }

    /// `log p(theta | x)`: the density over the parameters themselves (the
    /// standardization's and the supports' Jacobians included).
    ///
    /// # Errors
    /// Features or parameters of the wrong length or not finite.
    pub fn log_density(&self, x: &[f64], theta: &[f64]) -> Result<f64> {
        let mut out = [0.0];
        self.log_densities(x, theta, &mut out)?;
        Ok(out[0])
    }

    /// [`Self::log_density`] of each parameter vector of `thetas` (rows
    /// after row) into `out`, the network run once for them all: what
    /// the region of highest density takes of a record's draws.
    ///
    /// # Errors
    /// Features not finite or of the wrong length, or `thetas` not a row
    /// of parameters per entry of `out`.
    pub fn log_densities(&self, x: &[f64], thetas: &[f64], out: &mut [f64]) -> Result<()> {
        let head = self.head(x)?;
        let d = self.shape.dim;
        if thetas.len() != out.len() * d {
            return Err(FitError::ShapeMismatch(format!(
                "{} values for {} vectors of {d} parameters",
                thetas.len(),
                out.len()
            )));
        }
        for (theta, out) in thetas.chunks_exact(d).zip(out.iter_mut()) {
            let mut z = [0.0f64; MAX_WIDTH];
            let mut jacobian = 0.0;
            for (j, (&v, support)) in theta.iter().zip(&self.supports).enumerate() {
                z[j] = support.to_unbounded(v);
                jacobian += support.log_jacobian(v) - self.unbounded.scale()[j].ln();
            }
            let mut zs = [0.0f64; MAX_WIDTH];
            self.unbounded.transform_into(&z[..d], &mut zs[..d]);
            *out = self.shape.log_density(&head, &zs[..d]) + jacobian;
        }
        Ok(())
    }

    /// The smallest level of the region of highest density given `x`
    /// that holds `at`, by `draws` (draws x parameters, row after row,
    /// from this density given `x`): the share of the draws the density
    /// finds more probable than `at`. `at` lies inside the joint region of
    /// level q (e.g. 0.9) where this is at most q; a level near 1 says the
    /// values are far in the posterior's tails.
    ///
    /// # Errors
    /// Features, draws or `at` of the wrong length or not finite, or `at`
    /// outside a parameter's support.
    pub fn region_level(&self, x: &[f64], draws: &[f64], at: &[f64]) -> Result<f64> {
        let d = self.shape.dim;
        if at.len() != d {
            return Err(FitError::ShapeMismatch(format!(
                "{} values to test, the density is of {d} parameters",
                at.len()
            )));
        }
        if let Some(j) = (0..d).find(|&j| !inside(self.supports[j], at[j])) {
            return Err(invalid(
                "values to test",
                format!("parameter {j}: {}", at[j]),
                &format!("inside its support {:?}", self.supports[j]),
            ));
        }
        let mut densities = vec![0.0; draws.len() / d];
        self.log_densities(x, draws, &mut densities)?;
        let at_density = self.log_density(x, at)?;
        let above = densities.iter().filter(|&&v| v > at_density).count();
        Ok(above as f64 / densities.len().max(1) as f64)
    }

    /// Draws of `θ` given the features `x` into `out` (draws x parameters,
    /// row after row: as many draws as `out` holds rows), each within its
    /// parameter's support.
    ///
    /// # Errors
    /// Features of the wrong length or not finite, or `out` not a whole
    /// number of draws.
    pub fn sample(&self, x: &[f64], rng: &mut impl Rng, out: &mut [f64]) -> Result<()> {
        let d = self.shape.dim;
        if !out.len().is_multiple_of(d) {
            return Err(FitError::ShapeMismatch(format!(
                "{} values do not make draws of {d} parameters",
                out.len()
            )));
        }
        let head = self.head(x)?;
        let mut normals = [0.0f64; MAX_WIDTH];
        let mut words = || rng.next_u64();
        for draw in out.chunks_exact_mut(d) {
            self.shape
                .draw_from_words(&head, &mut words, &mut normals[..d], draw);
            self.unbounded.inverse_in_place(draw);
            for (v, support) in draw.iter_mut().zip(&self.supports) {
                *v = support.from_unbounded(*v);
            }
        }
        Ok(())
    }

    /// Mean negative log-likelihood of `theta` given `x` (rows of each),
    /// over the parameters themselves: the score by which densities are
    /// compared on held-out records.
    ///
    /// # Errors
    /// As [`Self::log_density`], for the first row that fails.
    pub fn mean_nll(&self, x: ArrayView2<'_, f64>, theta: ArrayView2<'_, f64>) -> Result<f64> {
        if x.nrows() != theta.nrows() {
            return Err(FitError::ShapeMismatch(format!(
                "{} feature rows, {} parameter rows",
                x.nrows(),
                theta.nrows()
            )));
        }
        let mut sum = 0.0;
        for (xr, tr) in x.rows().into_iter().zip(theta.rows()) {
            sum -= self.log_density(&xr.to_vec(), &tr.to_vec())?;
        }
        Ok(sum / x.nrows().max(1) as f64)
    }
}

#[cfg(test)]
mod tests;
