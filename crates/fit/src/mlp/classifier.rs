//! A two-class classifier: a tanh network whose one output is the log
//! odds of the second class, trained by the negative log-likelihood of
//! the labels (logistic loss) through the density's L-BFGS restarts; and
//! the classifier two-sample test that scores a posterior's draws against
//! reference draws (Lopez-Paz and Oquab, "Revisiting classifier
//! two-sample tests", ICLR 2017; the recipe of Lueckmann et al.,
//! "Benchmarking simulation-based inference", AISTATS 2021: an MLP,
//! k-fold cross-validated accuracy, 0.5 where the two samples are alike).

use ndarray::{Array2, ArrayView2, Axis};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::error::{FitError, InvalidSetting, Result};
use crate::standardize::Standardizer;

use super::likelihood::{DensityRestart, Head, fit_network, head_of};
use super::network::MAX_WIDTH;
use super::params::{Mlp, MlpParams};

/// How a classifier learns: the network (hidden layers, restarts,
/// held-out fraction, patience, weight decay, seed, deadline) and the
/// L-BFGS iterations of each restart.
///
/// ```
/// use ndarray::Array2;
/// use twostage_fit::{Classifier, MlpParams};
/// // The class is the sign of x0 + x1.
/// let x = Array2::from_shape_fn((400, 2), |(i, j)| ((i * (7 + 6 * j)) % 97) as f64 / 48.0 - 1.0);
/// let labels: Vec<bool> = x.rows().into_iter().map(|r| r[0] + r[1] > 0.0).collect();
/// let network = MlpParams::new(&[6])?.restarts(1).seed(2).check()?;
/// let classifier = Classifier::new(network)?.fit(x.view(), &labels)?;
/// assert!(classifier.probability(&[0.8, 0.5])? > 0.9);
/// assert!(classifier.accuracy(x.view(), &labels)? > 0.95);
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Classifier {
    network: MlpParams,
    iterations: usize,
}

/// A trained classifier: the probability of the second class.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedClassifier {
    features: Standardizer,
    sizes: Vec<usize>,
    params: Vec<f64>,
    reports: Vec<DensityRestart>,
    best: usize,
}

/// The Bernoulli of a label (0 or 1) given its log odds `o`:
/// `−log p = softplus(o) − label · o`.
#[derive(Debug, Clone, Copy)]
struct LogOdds;

impl Head for LogOdds {
    fn nll(&self, head: &[f64], target: &[f64]) -> f64 {
        let o = head[0];
        // softplus(o) = max(o, 0) + log(1 + e^-|o|), exact for any |o|.
        o.max(0.0) + (-o.abs()).exp().ln_1p() - target[0] * o
    }

    fn gradient(&self, head: &[f64], target: &[f64], scale: f64, delta: &mut [f64]) {
        delta[0] = scale * (sigmoid(head[0]) - target[0]);
    }
}

fn sigmoid(o: f64) -> f64 {
    if o >= 0.0 {
        1.0 / (1.0 + (-o).exp())
    } else {
        let e = o.exp();
        e / (1.0 + e)
    }
}

fn invalid(name: &'static str, value: String, reason: &str) -> FitError {
    FitError::InvalidSetting(InvalidSetting {
        name,
        value,
        reason: reason.into(),
    })
}

impl Classifier {
    /// L-BFGS iterations a restart unless set otherwise.
    pub const DEFAULT_ITERATIONS: usize = 1000;

    /// A classifier given by `network`.
    ///
    /// # Errors
    /// An ensemble asked of the network (a classifier is one network).
    pub fn new(network: Mlp) -> Result<Self> {
        let network = network.params().clone();
        if network.ensemble {
            return Err(invalid(
                "ensemble",
                "true".into(),
                "a classifier is one network: leave the ensemble out",
            ));
        }
        Ok(Self {
            network,
            iterations: Self::DEFAULT_ITERATIONS,
        })
    }

    /// At most `iterations` L-BFGS iterations a restart.
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

    /// The same classifier seeded by `seed` (its weights and held-out rows).
    pub fn seeded(&self, seed: u64) -> Self {
        let mut seeded = self.clone();
        seeded.network.seed = seed;
        seeded
    }

    /// Learn `labels` (true: the second class) from the rows of `x`.
    ///
    /// # Errors
    /// Not a label per row, non-finite values, or too few rows.
    pub fn fit(&self, x: ArrayView2<'_, f64>, labels: &[bool]) -> Result<FittedClassifier> {
        let targets = Array2::from_shape_fn((labels.len(), 1), |(i, _)| f64::from(labels[i]));
        crate::check::training_data(x, targets.view())?;
        let n_in = x.ncols();
        if n_in > MAX_WIDTH {
            return Err(invalid(
                "features",
                n_in.to_string(),
                "at most 256 features a row",
            ));
        }
        let p = &self.network;
        let features = Standardizer::fit(x);
        let xs = features.transform(x).as_standard_layout().to_owned();
        let (sizes, params, reports, best) =
            fit_network(LogOdds, 1, (&xs, &targets), p, self.iterations)?;
        Ok(FittedClassifier {
            features,
            sizes,
            params,
            reports,
            best,
        })
    }
}

impl FittedClassifier {
    /// The probability that `x` is of the second class.
    ///
    /// # Errors
    /// A row of the wrong length or not finite.
    pub fn probability(&self, x: &[f64]) -> Result<f64> {
        let head = head_of(
            &self.features,
            (&self.sizes, &self.params),
            x,
            "the classifier",
        )?;
        Ok(sigmoid(head[0]))
    }

    /// The share of the rows of `x` whose more probable class is their
    /// label.
    ///
    /// # Errors
    /// Not a label per row, or as [`Self::probability`].
    pub fn accuracy(&self, x: ArrayView2<'_, f64>, labels: &[bool]) -> Result<f64> {
        if x.nrows() != labels.len() {
            return Err(FitError::ShapeMismatch(format!(
                "{} rows, {} labels",
                x.nrows(),
                labels.len()
            )));
        }
        let mut right = 0usize;
        for (row, &label) in x.rows().into_iter().zip(labels) {
            let p = self.probability(&row.to_vec())?;
            right += usize::from((p > 0.5) == label);
        }
        Ok(right as f64 / labels.len().max(1) as f64)
    }

    /// One report per restart.
    pub fn reports(&self) -> &[DensityRestart] {
        &self.reports
    }

    /// The restart kept: the lowest held-out negative log-likelihood.
    pub fn best_restart(&self) -> &DensityRestart {
        &self.reports[self.best]
    }
}

/// The classifier two-sample test: how well `classifier` tells the rows
/// of `first` from those of `second` (both rows x dimensions), as its
/// accuracy on rows it did not learn from, averaged over `folds` folds of
/// the pooled rows shuffled by the classifier's seed. About 0.5 where the
/// two samples come from one distribution, 1 where they do not overlap;
/// each fold's classifier standardizes the rows it learns from (sbibm
/// standardizes by the first sample's mean and spread: another shift and
/// scale, which the network's first layer absorbs).
///
/// ```
/// use ndarray::Array2;
/// use twostage_fit::{Classifier, MlpParams, two_sample_accuracy};
/// let grid = |shift: f64| Array2::from_shape_fn((300, 1), |(i, _)| (i as f64 / 299.0) + shift);
/// let network = MlpParams::new(&[4])?.restarts(1).seed(1).check()?;
/// let classifier = Classifier::new(network)?;
/// let apart = two_sample_accuracy(grid(0.0).view(), grid(2.0).view(), 5, &classifier)?;
/// assert!(apart > 0.99, "{apart}");
/// # Ok::<(), twostage_fit::FitError>(())
/// ```
///
/// # Errors
/// Samples of different dimensions, fewer than 2 folds, a fold with too
/// few rows to learn from, or as [`Classifier::fit`].
pub fn two_sample_accuracy(
    first: ArrayView2<'_, f64>,
    second: ArrayView2<'_, f64>,
    folds: usize,
    classifier: &Classifier,
) -> Result<f64> {
    if first.ncols() != second.ncols() {
        return Err(FitError::ShapeMismatch(format!(
            "samples of {} and {} dimensions",
            first.ncols(),
            second.ncols()
        )));
    }
    let rows = first.nrows() + second.nrows();
    if folds < 2 || rows < 2 * folds {
        return Err(invalid(
            "folds",
            format!("{folds} folds of {rows} rows"),
            "at least 2 folds, each of at least 2 rows",
        ));
    }
    let pooled = ndarray::concatenate(Axis(0), &[first, second])
        .map_err(|e| FitError::ShapeMismatch(e.to_string()))?;
    let labels: Vec<bool> = (0..rows).map(|i| i >= first.nrows()).collect();
    let mut order: Vec<usize> = (0..rows).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(
        classifier.network.seed ^ 0x4332_5354,
    ));
    let mut accuracy = 0.0;
    for fold in 0..folds {
        let (start, end) = (fold * rows / folds, (fold + 1) * rows / folds);
        let test = &order[start..end];
        let train: Vec<usize> = order[..start]
            .iter()
            .chain(&order[end..])
            .copied()
            .collect();
        let fitted = classifier
            .seeded(classifier.network.seed.wrapping_add(fold as u64))
            .fit(
                pooled.select(Axis(0), &train).view(),
                &train.iter().map(|&i| labels[i]).collect::<Vec<_>>(),
            )?;
        accuracy += fitted.accuracy(
            pooled.select(Axis(0), test).view(),
            &test.iter().map(|&i| labels[i]).collect::<Vec<_>>(),
        )?;
    }
    Ok(accuracy / folds as f64)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use rand::RngExt;
    use rand_distr::StandardNormal;

    use super::super::lbfgs::Objective;
    use super::super::likelihood::Likelihood;
    use super::*;

    fn network(hidden: &[usize], seed: u64) -> Classifier {
        Classifier::new(
            MlpParams::new(hidden)
                .unwrap()
                .restarts(1)
                .seed(seed)
                .check()
                .unwrap(),
        )
        .unwrap()
    }

    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        rng.sample(StandardNormal)
    }

    /// The logistic loss's gradient by back-propagation against central
    /// differences of the loss, every weight.
    #[test]
    fn the_logistic_gradient_matches_finite_differences() {
        let sizes = [2, 4, 1];
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let x = Array2::from_shape_fn((9, 2), |_| rng.random_range(-1.5..1.5));
        let z = Array2::from_shape_fn((9, 1), |(i, _)| f64::from(i % 3 == 0));
        let train: Vec<usize> = (0..9).collect();
        let likelihood = Likelihood {
            sizes: &sizes,
            offsets: vec![0, 2, 6, 7],
            head: LogOdds,
            x: &x,
            z: &z,
            train: &train,
            held_out: &train,
            decay: 0.1,
        };
        let params: Vec<f64> = (0..super::super::network::parameter_count(&sizes))
            .map(|_| rng.random_range(-2.0..2.0))
            .collect();
        let mut grad = vec![0.0; params.len()];
        likelihood.gradient(&params, &mut grad);
        let h = 1e-6;
        for (w, &g) in grad.iter().enumerate() {
            let (mut plus, mut minus) = (params.clone(), params.clone());
            plus[w] += h;
            minus[w] -= h;
            let numeric = (likelihood.loss(&plus) - likelihood.loss(&minus)) / (2.0 * h);
            assert!(
                (g - numeric).abs() < 1e-7 * (1.0 + numeric.abs()),
                "weight {w}: {g} against {numeric}"
            );
        }
        // The loss of a far-out log odds is exact, not overflowed.
        assert!(LogOdds.nll(&[800.0], &[1.0]).abs() < 1e-300);
        assert!((LogOdds.nll(&[-800.0], &[1.0]) - 800.0).abs() < 1e-12);
    }

    /// Labels drawn with P(1 | x) = sigmoid(2x): the fitted probability
    /// is the closed form's, within what 4000 rows tell.
    #[test]
    fn a_logistic_law_is_learned() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x = Array2::from_shape_fn((4000, 1), |_| rng.random_range(-2.0..2.0));
        let labels: Vec<bool> = (0..4000)
            .map(|i| rng.random::<f64>() < sigmoid(2.0 * x[[i, 0]]))
            .collect();
        let fitted = network(&[4], 1).fit(x.view(), &labels).unwrap();
        for at in [-1.5, -0.5, 0.0, 0.4, 1.2] {
            let p = fitted.probability(&[at]).unwrap();
            assert!(
                (p - sigmoid(2.0 * at)).abs() < 0.05,
                "at {at}: {p} against {}",
                sigmoid(2.0 * at)
            );
        }
    }

    /// Two unit normals `d` apart are told apart at best with accuracy
    /// Φ(d/2); one distribution twice, at 0.5.
    #[test]
    fn the_two_sample_accuracy_is_the_closed_forms() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let sample = |shift: f64, rng: &mut ChaCha8Rng| {
            Array2::from_shape_fn((3000, 2), |(_, j)| {
                normal(rng) + if j == 0 { shift } else { 0.0 }
            })
        };
        let reference = sample(0.0, &mut rng);
        let same = sample(0.0, &mut rng);
        let shifted = sample(1.0, &mut rng);
        let classifier = network(&[8, 8], 5);
        let alike = two_sample_accuracy(reference.view(), same.view(), 5, &classifier).unwrap();
        assert!((alike - 0.5).abs() < 0.025, "{alike}");
        // Φ(0.5) = 0.691462.
        let apart = two_sample_accuracy(reference.view(), shifted.view(), 5, &classifier).unwrap();
        assert!((apart - 0.691462).abs() < 0.02, "{apart}");
    }

    #[test]
    fn samples_or_folds_that_cannot_be_tested_are_refused() {
        let classifier = network(&[2], 1);
        let a = Array2::<f64>::zeros((10, 2));
        let b = Array2::<f64>::zeros((10, 3));
        assert!(matches!(
            two_sample_accuracy(a.view(), b.view(), 5, &classifier),
            Err(FitError::ShapeMismatch(_))
        ));
        assert!(matches!(
            two_sample_accuracy(a.view(), a.view(), 1, &classifier),
            Err(FitError::InvalidSetting(_))
        ));
        let fitted = network(&[2], 1)
            .fit(
                Array2::from_shape_fn((20, 2), |(i, j)| (i + j) as f64).view(),
                &(0..20).map(|i| i % 2 == 0).collect::<Vec<_>>(),
            )
            .unwrap();
        assert!(fitted.probability(&[1.0]).is_err());
        assert!(fitted.probability(&[1.0, f64::NAN]).is_err());
        assert!(
            Classifier::new(
                MlpParams::new(&[2])
                    .unwrap()
                    .ensemble(true)
                    .check()
                    .unwrap()
            )
            .is_err()
        );
    }
}
