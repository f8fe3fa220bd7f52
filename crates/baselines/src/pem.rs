//! The prediction-error method (Section 2.2 of the paper): minimize the sum
//! of squared one-step prediction errors over theta in the prior box, by
//! Levenberg-Marquardt with finite-difference derivatives, from several
//! seeded random starts, keeping the lowest loss.

use std::ops::ControlFlow;

use twostage_fit::{Damping, LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use twostage_models::{IoData, Prior};

use crate::error::{BaselineError, Result};
use crate::kalman::benchmark_kalman_innovations;
use crate::moments::WeightedMoments;
use crate::{Estimate, RecordEstimator};

/// A model whose prediction errors on a record can be computed at any theta.
pub trait ResidualModel: Send + Sync {
    /// The prior box.
    fn prior(&self) -> &Prior;
    /// Write the residuals of `record` at `theta` into `residuals`, whose
    /// squares sum to the loss: prediction errors, one per sample, unless
    /// [`ResidualModel::n_residuals`] says otherwise.
    ///
    /// # Errors
    /// A record the model cannot use, or a prediction that fails.
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<()>;

    /// How many residuals `record` gives (default: one per sample).
    fn n_residuals(&self, record: &IoData) -> usize {
        record.n_samples()
    }
}

/// The benchmark with its exact Kalman predictor: the PE estimate is then
/// also the maximum-likelihood estimate up to the innovation variances.
#[derive(Debug, Clone)]
pub struct BenchmarkPredictor {
    prior: Prior,
}

impl BenchmarkPredictor {
    /// The paper's benchmark, theta in [-0.9, 0.9].
    ///
    /// # Errors
    /// Never for the built-in box.
    pub fn new() -> Result<Self> {
        Ok(Self {
            prior: Prior::uniform_box(&[-0.9], &[0.9])?,
        })
    }
}

impl ResidualModel for BenchmarkPredictor {
    fn prior(&self) -> &Prior {
        &self.prior
    }
    fn residuals(&self, theta: &[f64], record: &IoData, residuals: &mut [f64]) -> Result<()> {
        benchmark_kalman_innovations(theta[0], record, Some(residuals)).map(|_| ())
    }
}

/// The result of [`PredictionError::local_posterior`].
#[derive(Debug, Clone, PartialEq)]
pub struct LocalPosterior {
    /// The posterior mean over the box.
    pub mean: Vec<f64>,
    /// The posterior standard deviation over the box.
    pub sd: Vec<f64>,
    /// Loss evaluations spent.
    pub evaluations: usize,
}

/// Where [`PredictionError::refine`] starts its descents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefineStarts {
    /// One descent from the given start.
    Centre,
    /// That, and one from each side of it along each axis.
    CentreAndAxes,
}

/// One descent from one start.
#[derive(Debug, Clone, PartialEq)]
pub struct Descent {
    /// Where it started.
    pub start: Vec<f64>,
    /// Where it ended.
    pub theta: Vec<f64>,
    /// The loss there.
    pub loss: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: TerminationReason,
}

/// The prediction-error estimator with multi-start.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `starts` | 1 | >= 1 seeded uniform draws from the prior |
/// | `max_iterations` | 50 | >= 1 per start |
/// | `seed` | 0 | any |
///
/// ```
/// use twostage_baselines::{BenchmarkPredictor, PredictionError, RecordEstimator};
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.5], &mut experiment_rng(11, 0), &mut record)?;
/// let pem = PredictionError::new(BenchmarkPredictor::new()?, 10).seed(1);
/// let descents = pem.descents(&record)?;
/// // The estimate is the end of the descent with the lowest loss; on this
/// // record it is the global minimum near the truth. (On others a local
/// // minimum a few hundredths away has almost the same loss: the
/// // sin(50 theta^2) term makes the loss oscillate, as the paper warns.)
/// assert!(descents.windows(2).all(|w| w[0].loss <= w[1].loss));
/// assert!((pem.estimate(&record)?.theta[0] - 0.5).abs() < 0.03);
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
#[derive(Debug, Clone)]
pub struct PredictionError<M> {
    model: M,
    starts: usize,
    max_iterations: usize,
    seed: u64,
    name: String,
}

impl<M: ResidualModel> PredictionError<M> {
    /// PE with `starts` random starts.
    pub fn new(model: M, starts: usize) -> Self {
        Self {
            model,
            starts,
            max_iterations: 50,
            seed: 0,
            name: format!("pem{starts}"),
        }
    }

    /// The seed of the starting points.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Another name for tables (default `pem<starts>`).
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// The residual model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// Iterations per start.
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self
    }

    /// Run every descent and return them all, best first.
    ///
    /// # Errors
    /// A bad record, or no start at all.
    pub fn descents(&self, record: &IoData) -> Result<Vec<Descent>> {
        if self.starts == 0 || self.max_iterations == 0 {
            return Err(BaselineError::InvalidSetting {
                name: "starts and iterations",
                value: format!("{} and {}", self.starts, self.max_iterations),
                expected: "at least 1 each".into(),
            });
        }
        let prior = self.model.prior();
        let design = prior.design(self.starts, self.seed)?;
        let mut descents = Vec::with_capacity(self.starts);
        for i in 0..self.starts {
            let mut start = vec![0.0; prior.dim()];
            design.fill_theta(i, &mut start)?;
            descents.push(self.descend(record, start)?);
        }
        descents.sort_by(|a, b| a.loss.total_cmp(&b.loss));
        Ok(descents)
    }

    /// One Levenberg-Marquardt descent in the prior box (central
    /// differences, steps clipped to the box) from `start`: a local search,
    /// for a start that is already near the answer.
    ///
    /// # Errors
    /// A bad record, or a start of the wrong length.
    pub fn descend(&self, record: &IoData, start: Vec<f64>) -> Result<Descent> {
        let q = self.model.prior().dim();
        self.descend_within(record, start, &vec![0.0; q], &vec![1.0; q])
    }

    /// A local refinement of `start` (a TS estimate, say): descents
    /// confined to the box `start +- radius` (within the prior), keeping the
    /// lowest loss. The loss of an oscillating model has many basins; a good
    /// start lies in or next to the right one, and the confinement keeps the
    /// first Gauss-Newton steps from jumping out of the neighbourhood.
    /// [`RefineStarts::CentreAndAxes`] adds descents from `start +- radius/2`
    /// along each axis (each in its own part of the box), which finds the
    /// lowest basin of the box far more often, for 1 + 2q times the cost.
    ///
    /// # Errors
    /// A bad record, or `start` and `radius` of the wrong length.
    pub fn refine(
        &self,
        record: &IoData,
        start: &[f64],
        radius: &[f64],
        starts: RefineStarts,
    ) -> Result<Descent> {
        let prior = self.model.prior();
        let q = prior.dim();
        if radius.len() != q || start.len() != q || radius.iter().any(|r| r.is_nan() || *r < 0.0) {
            return Err(BaselineError::Shape {
                what: "the start and the radius",
                found: format!("{} and {} values", start.len(), radius.len()),
                expected: format!("{q} each (one per parameter), radii >= 0"),
            });
        }
        // The box in unit coordinates, and a start confined to a sub-box.
        let unit = |j: usize, t: f64| {
            ((t - prior.lower()[j]) / (prior.upper()[j] - prior.lower()[j])).clamp(0.0, 1.0)
        };
        let outer: Vec<(f64, f64)> = (0..q)
            .map(|j| (unit(j, start[j] - radius[j]), unit(j, start[j] + radius[j])))
            .collect();
        let (lo, hi): (Vec<f64>, Vec<f64>) = outer.iter().copied().unzip();
        let mut best = self.descend_within(record, start.to_vec(), &lo, &hi)?;
        if starts == RefineStarts::CentreAndAxes {
            for j in 0..q {
                for side in [-1.0, 1.0] {
                    let mut from = start.to_vec();
                    from[j] += side * 0.5 * radius[j];
                    // Its own half of the box along axis j.
                    let (mut l, mut h) = (lo.clone(), hi.clone());
                    let middle = unit(j, start[j]);
                    if side < 0.0 {
                        h[j] = middle;
                    } else {
                        l[j] = middle;
                    }
                    let descent = self.descend_within(record, from, &l, &h)?;
                    if descent.loss < best.loss {
                        best = descent;
                    }
                }
            }
        }
        Ok(best)
    }

    /// The posterior mean over the box `centre +- radius` (within the
    /// prior), treating the loss as a Gaussian negative log-likelihood:
    /// `p(theta | D) ~ exp(-(L(theta) - L_min) / (2 s^2))` with the residual
    /// variance `s^2 = L_min / n` estimated from the best grid point, and the
    /// uniform prior. It is evaluated on a tensor grid of `points` per axis
    /// (`points^q` evaluations of the loss), so it suits few parameters.
    ///
    /// Where a multi-modal loss makes the minimizer jump between basins (the
    /// benchmark's sin(50 theta^2)), the posterior mean averages them as the
    /// Bayes-optimal estimate does: with a TS estimate as centre it comes
    /// close to the global posterior mean at a fraction of its cost.
    ///
    /// # Errors
    /// A bad record, `centre`/`radius` of the wrong length, or fewer than 2
    /// points per axis.
    pub fn local_posterior(
        &self,
        record: &IoData,
        centre: &[f64],
        radius: &[f64],
        points: usize,
    ) -> Result<LocalPosterior> {
        let prior = self.model.prior();
        let q = prior.dim();
        if centre.len() != q
            || radius.len() != q
            || radius.iter().any(|r| r.is_nan() || *r < 0.0)
            || points < 2
        {
            return Err(BaselineError::Shape {
                what: "the centre, the radius and the points per axis",
                found: format!("{}, {} and {points}", centre.len(), radius.len()),
                expected: format!("{q}, {q} (radii >= 0) and at least 2"),
            });
        }
        let total = points
            .checked_pow(q as u32)
            .filter(|t| *t <= 1 << 20)
            .ok_or_else(|| BaselineError::InvalidSetting {
                name: "points per axis",
                value: points.to_string(),
                expected: format!("at most 2^20 grid points in all ({points}^{q} is more)"),
            })?;
        let axes: Vec<Vec<f64>> = (0..q)
            .map(|j| {
                let lo = (centre[j] - radius[j]).max(prior.lower()[j]);
                let hi = (centre[j] + radius[j]).min(prior.upper()[j]);
                (0..points)
                    .map(|i| lo + (hi - lo) * i as f64 / (points - 1) as f64)
                    .collect()
            })
            .collect();
        let n = self.model.n_residuals(record);
        let mut residuals = vec![0.0; n];
        let mut theta = vec![0.0; q];
        let mut grid = Vec::with_capacity(total);
        for index in 0..total {
            let mut rest = index;
            for (t, axis) in theta.iter_mut().zip(&axes) {
                *t = axis[rest % points];
                rest /= points;
            }
            self.model.residuals(&theta, record, &mut residuals)?;
            let loss: f64 = residuals.iter().map(|r| r * r).sum();
            grid.push((theta.clone(), loss));
        }
        let best = grid.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
        if !best.is_finite() {
            return Err(BaselineError::Numerical {
                sample: 0,
                what: "the loss is not finite anywhere on the local grid".into(),
            });
        }
        let variance = (best / n.max(1) as f64).max(f64::MIN_POSITIVE);
        let mut moments = WeightedMoments::new(q);
        for (t, loss) in &grid {
            moments.add((-(loss - best) / (2.0 * variance)).exp(), t);
        }
        let (mean, sd) = moments.mean_and_sd();
        Ok(LocalPosterior {
            mean,
            sd,
            evaluations: total,
        })
    }

    /// Levenberg-Marquardt from `start`, with every iterate in the box
    /// `[lo, hi]` of unit-box coordinates.
    fn descend_within(
        &self,
        record: &IoData,
        start: Vec<f64>,
        lo: &[f64],
        hi: &[f64],
    ) -> Result<Descent> {
        if start.len() != self.model.prior().dim() || self.max_iterations == 0 {
            return Err(BaselineError::Shape {
                what: "the start (and the iteration budget)",
                found: format!(
                    "{} values ({} iterations)",
                    start.len(),
                    self.max_iterations
                ),
                expected: format!("{} values (at least 1 iteration)", self.model.prior().dim()),
            });
        }
        let prior = self.model.prior();
        let unit: Vec<f64> = start
            .iter()
            .zip(prior.lower().iter().zip(prior.upper()))
            .map(|(t, (lo, hi))| (t - lo) / (hi - lo))
            .collect();
        let mut problem = PredictionErrors {
            model: &self.model,
            record,
            lo,
            hi,
            theta: Vec::with_capacity(unit.len()),
            unit_lower: vec![0.0; unit.len()],
            unit_upper: vec![1.0; unit.len()],
        };
        // Marquardt's scaling: the parameters' sensitivities differ by
        // orders of magnitude (the car's pK1 and pK2).
        let solver = LevenbergMarquardt::new()
            .max_iterations(self.max_iterations)
            .tolerance(1e-10)
            .damping(Damping::Diagonal { floor: 1e-12 })
            .initial_damping(1e-3)
            .max_damping(1e12f64.next_down());
        let found = solver.minimize(&mut problem, &unit, |_| ControlFlow::Continue(()))?;
        let theta = found
            .x
            .iter()
            .zip(prior.lower().iter().zip(prior.upper()))
            .map(|(si, (lo, hi))| lo + si * (hi - lo))
            .collect();
        Ok(Descent {
            start,
            theta,
            loss: found.cost,
            iterations: found.iterations,
            stop: found.reason,
        })
    }
}

/// The prediction errors of one record as a least-squares problem in the
/// prior box's unit coordinates, confined to the sub-box `[lo, hi]`.
struct PredictionErrors<'a, M> {
    model: &'a M,
    record: &'a IoData,
    lo: &'a [f64],
    hi: &'a [f64],
    theta: Vec<f64>,
    /// The whole prior box in unit coordinates: zeros and ones.
    unit_lower: Vec<f64>,
    unit_upper: Vec<f64>,
}

impl<M: ResidualModel> LeastSquaresProblem for PredictionErrors<'_, M> {
    type Error = BaselineError;

    fn residuals(&mut self, s: &[f64], r: &mut Vec<f64>) -> Result<()> {
        let prior = self.model.prior();
        self.theta.clear();
        self.theta.extend(
            s.iter()
                .zip(prior.lower().iter().zip(prior.upper()))
                .map(|(si, (lo, hi))| lo + si * (hi - lo)),
        );
        r.resize(self.model.n_residuals(self.record), 0.0);
        self.model.residuals(&self.theta, self.record, r)
    }

    /// The prior box, in unit coordinates: the model is not defined
    /// outside it, so the finite differences step inward at its faces.
    fn domain(&self) -> Option<(&[f64], &[f64])> {
        Some((&self.unit_lower, &self.unit_upper))
    }

    fn project(&self, s: &mut [f64]) {
        for ((v, lo), hi) in s.iter_mut().zip(self.lo).zip(self.hi) {
            *v = v.clamp(*lo, *hi);
        }
    }
}

impl<M: ResidualModel> RecordEstimator for PredictionError<M> {
    fn name(&self) -> &str {
        &self.name
    }

    fn estimate(&self, record: &IoData) -> Result<Estimate> {
        let best = self.descents(record)?.into_iter().next().ok_or_else(|| {
            BaselineError::InvalidSetting {
                name: "starts",
                value: self.starts.to_string(),
                expected: "at least 1".into(),
            }
        })?;
        Ok(Estimate {
            theta: best.theta,
            spread: None,
        })
    }
}
