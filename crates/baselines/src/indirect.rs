//! Indirect inference (Sections 2.3 and 4.4 of the paper): the paradigm
//! closest to TS. Both pass through an intermediate black-box model, here
//! the same ARX compressor as the TS presets; but II defines the estimate
//! implicitly, by an optimization per record,
//!
//! ```text
//! theta_hat = argmin_theta (beta(D) - beta_bar(theta))' W (beta(D) - beta_bar(theta)),
//! beta_bar(theta) = (1/S) sum_s g(simulate(theta, seed_s)),
//! ```
//!
//! while TS learns the explicit map from beta to theta once.
//!
//! The S simulations at every theta use the same random streams (common
//! random numbers), so beta_bar is a smooth function of theta and the
//! Levenberg-Marquardt descent of [`PredictionError`] applies unchanged:
//! with `W = C^-1` and `C = L L'` (Cholesky) the loss is `||L^-1 (beta(D) -
//! beta_bar(theta))||^2`, a sum of squared residuals.

use crate::InvalidSetting;
use rayon::prelude::*;
use twostage_compress::{Compressor, Workspace};
use twostage_fit::CovarianceFactor;
use twostage_kernels::cholesky::solve_lower_in_place;
use twostage_models::{IoData, Prior, Simulator, experiment_rng};
use twostage_refine::ResidualModel;

use crate::error::{BaselineError, Result};
use crate::pem::PredictionError;

/// The weighting matrix W of the II loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Weighting {
    /// W = I: plain squared distance between coefficient vectors.
    Identity,
    /// W = C^-1, with C the sample covariance of the compressed features of
    /// `simulations` records simulated at the prior's centre (the
    /// efficient choice for the II estimator, Gourieroux et al. 1993).
    InverseCovariance {
        /// Records simulated to estimate C (more than the feature count).
        simulations: usize,
    },
}

/// Common simulation s of seed `seed` runs on
/// `experiment_rng(seed ^ COMMON_NUMBERS_SEED, s)` for every theta.
pub const COMMON_NUMBERS_SEED: u64 = 0x4949_434f_4d4d_4f4e; // "IICOMMON"
/// Weighting record i of seed `seed` runs on
/// `experiment_rng(seed ^ WEIGHTING_SEED, i)`, at the prior's centre: a
/// stream apart from the common numbers.
pub const WEIGHTING_SEED: u64 = 0x4949_5745_4947_4854; // "IIWEIGHT"

/// The II loss of one record as residuals, for the Levenberg-Marquardt
/// descent of [`PredictionError`].
#[derive(Debug, Clone)]
pub struct IndirectObjective<S, C> {
    simulator: S,
    compressor: C,
    simulations: usize,
    seed: u64,
    /// Lower-triangular Cholesky factor of C, row-major, or `None` for W = I.
    factor: Option<Vec<f64>>,
}

impl<S: Simulator, C: Compressor + Send + Sync> IndirectObjective<S, C> {
    /// The objective with `simulations` (S) records per theta, all on the
    /// streams of `seed`, and the weighting `weighting`.
    ///
    /// # Errors
    /// S = 0, too few weighting records, a simulation or compression that
    /// fails, or a singular feature covariance.
    pub fn new(
        simulator: S,
        compressor: C,
        simulations: usize,
        weighting: Weighting,
        seed: u64,
    ) -> Result<Self> {
        if simulations == 0 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "simulations per theta",
                value: "0".into(),
                reason: "at least 1".into(),
            }));
        }
        let mut objective = Self {
            simulator,
            compressor,
            simulations,
            seed,
            factor: None,
        };
        if let Weighting::InverseCovariance { simulations } = weighting {
            objective.factor = Some(objective.covariance_factor(simulations)?);
        }
        Ok(objective)
    }

    /// Cholesky factor of the features' covariance at the prior's centre.
    fn covariance_factor(&self, count: usize) -> Result<Vec<f64>> {
        let n = self.compressor.n_features();
        if count <= n {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "weighting simulations",
                value: count.to_string(),
                reason: format!("more than the {n} features, to estimate their covariance"),
            }));
        }
        let prior = self.simulator.prior();
        let centre: Vec<f64> = prior
            .lower()
            .iter()
            .zip(prior.upper())
            .map(|(lo, hi)| 0.5 * (lo + hi))
            .collect();
        let mut record = IoData::default();
        let mut work = Workspace::new();
        let mut features = vec![0.0; count * n];
        for (i, alpha) in features.chunks_exact_mut(n).enumerate() {
            let mut rng = experiment_rng(self.seed ^ WEIGHTING_SEED, i as u64);
            self.simulator.simulate(&centre, &mut rng, &mut record)?;
            self.compressor
                .compress_into(record.inputs(), record.outputs(), &mut work, alpha)?;
        }
        let rows = ndarray::ArrayView2::from_shape((count, n), &features)
            .unwrap_or_else(|_| unreachable!("count rows of n features"));
        let covariance = CovarianceFactor::of_rows(rows).ok_or_else(|| {
            BaselineError::InvalidSetting(InvalidSetting {
                name: "weighting",
                value: "inverse covariance".into(),
                reason: "a weighting that exists: the features' covariance at the prior's \
                           centre is singular (a feature does not vary), use \
                           Weighting::Identity"
                    .into(),
            })
        })?;
        Ok(covariance.factor)
    }

    /// The Cholesky factor L of the features' covariance C = L L'
    /// (row-major, lower triangular), or `None` for W = I.
    pub fn weighting_factor(&self) -> Option<&[f64]> {
        self.factor.as_deref()
    }

    /// beta_bar(theta): the mean compressed vector over the S common streams.
    ///
    /// The S simulations run in parallel; their features are summed in
    /// stream order, so the result is the same bits on any thread count.
    ///
    /// # Errors
    /// A simulation or compression that fails, or `out` of the wrong length.
    pub fn mean_features(&self, theta: &[f64], out: &mut [f64]) -> Result<()> {
        let n = self.compressor.n_features();
        if out.len() != n {
            return Err(BaselineError::Shape {
                what: "the feature buffer",
                found: format!("{} slots", out.len()),
                expected: format!("{n}, one per feature"),
            });
        }
        let mut features = vec![0.0; self.simulations * n];
        features
            .par_chunks_mut(n)
            .enumerate()
            .map_init(
                || (IoData::default(), Workspace::new()),
                |(record, work), (s, alpha)| -> Result<()> {
                    let mut rng = experiment_rng(self.seed ^ COMMON_NUMBERS_SEED, s as u64);
                    self.simulator.simulate(theta, &mut rng, record)?;
                    self.compressor.compress_fast_into(
                        record.inputs(),
                        record.outputs(),
                        work,
                        alpha,
                    )?;
                    Ok(())
                },
            )
            .collect::<Result<()>>()?;
        out.fill(0.0);
        for alpha in features.chunks_exact(n) {
            for (o, a) in out.iter_mut().zip(alpha) {
                *o += a;
            }
        }
        for o in out.iter_mut() {
            *o /= self.simulations as f64;
        }
        Ok(())
    }

    /// The loss `(beta(D) - beta_bar)' W (beta(D) - beta_bar)` at theta.
    ///
    /// # Errors
    /// As [`ResidualModel::residuals`].
    pub fn loss(&self, theta: &[f64], record: &IoData) -> Result<f64> {
        let mut r = vec![0.0; self.compressor.n_features()];
        self.residuals(theta, record, &mut r)?;
        Ok(r.iter().map(|v| v * v).sum())
    }
}

impl<S: Simulator, C: Compressor + Send + Sync> ResidualModel for IndirectObjective<S, C> {
    type Error = BaselineError;
    fn prior(&self) -> &Prior {
        self.simulator.prior()
    }

    fn n_residuals(&self, _record: &IoData) -> usize {
        self.compressor.n_features()
    }

    /// `L^-1 (beta_bar(theta) - beta(D))`, or the plain difference for W = I.
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<()> {
        let n = self.compressor.n_features();
        if residuals.len() != n {
            return Err(BaselineError::Shape {
                what: "the residual buffer",
                found: format!("{} slots", residuals.len()),
                expected: format!("{n}, one per feature"),
            });
        }
        // beta(D) is recompressed at every evaluation: one record against
        // the S simulated ones, a small share of the cost.
        let mut data = vec![0.0; n];
        self.compressor.compress_fast_into(
            record.inputs(),
            record.outputs(),
            &mut Workspace::new(),
            &mut data,
        )?;
        self.mean_features(theta, residuals)?;
        for (r, d) in residuals.iter_mut().zip(&data) {
            *r -= d;
        }
        if let Some(l) = &self.factor {
            solve_lower_in_place(&l[..], n, residuals);
        }
        Ok(())
    }
}

/// The indirect-inference estimator: [`IndirectObjective`] minimized in the
/// prior box by Levenberg-Marquardt from seeded random starts.
///
/// | setting | default | valid |
/// |---|---|---|
/// | S, simulations per theta | 10 | >= 1 |
/// | weighting | inverse covariance from 200 records | [`Weighting`] |
/// | starts | 5 | >= 1 |
/// | seed | 0 | any (starts, common random numbers, weighting records) |
///
/// ```
/// use twostage_baselines::{IndirectInference, RecordEstimator, Weighting};
/// use twostage_compress::Arx;
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
///
/// let model = Benchmark::new();
/// let ii = IndirectInference::new(model.clone(), Arx::new(5, 5)?, 5)
///     .simulations(10)
///     .weighting(Weighting::InverseCovariance { simulations: 200 })
///     .seed(1)
///     .build()?;
/// assert_eq!(ii.name(), "ii5");
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.6], &mut experiment_rng(3, 0), &mut record)?;
/// // Like PE, the estimate is the end of the descent with the lowest loss;
/// // the loss oscillates in theta as the likelihood does, so a start far
/// // from the truth can end in a local minimum.
/// let descents = ii.descents(&record)?;
/// assert!(descents.windows(2).all(|w| w[0].loss <= w[1].loss));
/// assert_eq!(ii.estimate(&record)?.theta, descents[0].theta);
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
#[derive(Debug, Clone)]
pub struct IndirectInference<S, C> {
    simulator: S,
    compressor: C,
    starts: usize,
    simulations: usize,
    weighting: Weighting,
    seed: u64,
}

impl<S: Simulator, C: Compressor + Send + Sync> IndirectInference<S, C> {
    /// II for `simulator` through `compressor`, from `starts` random starts.
    pub fn new(simulator: S, compressor: C, starts: usize) -> Self {
        Self {
            simulator,
            compressor,
            starts,
            simulations: 10,
            weighting: Weighting::InverseCovariance { simulations: 200 },
            seed: 0,
        }
    }
    /// S, the simulations averaged at every theta.
    pub fn simulations(mut self, simulations: usize) -> Self {
        self.simulations = simulations;
        self
    }
    /// The weighting matrix W.
    pub fn weighting(mut self, weighting: Weighting) -> Self {
        self.weighting = weighting;
        self
    }
    /// The seed of the starts, the common random numbers and the weighting.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Estimate W and return the estimator.
    ///
    /// # Errors
    /// As [`IndirectObjective::new`], and no start.
    pub fn build(self) -> Result<PredictionError<IndirectObjective<S, C>>> {
        if self.starts == 0 {
            return Err(BaselineError::InvalidSetting(InvalidSetting {
                name: "starts",
                value: "0".into(),
                reason: "at least 1".into(),
            }));
        }
        let objective = IndirectObjective::new(
            self.simulator,
            self.compressor,
            self.simulations,
            self.weighting,
            self.seed,
        )?;
        Ok(PredictionError::new(objective, self.starts)
            .seed(self.seed)
            .named(format!("ii{}", self.starts)))
    }
}
