//! Training: seeded restarts in parallel, each by Levenberg-Marquardt (the
//! crate's one least-squares solver), Adam or L-BFGS, with early stopping on a held-out split;
//! within a restart the rows are divided over the threads in fixed blocks
//! (docs/decisions/026), so the weights do not depend on the thread count.

use crate::InvalidSetting;
use std::ops::ControlFlow;

use faer::Mat;
use ndarray::ArrayView2;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::Regressor;
use crate::check;
use crate::error::{FitError, Result};
use crate::levenberg_marquardt::{
    Damping, LeastSquaresProblem, LevenbergMarquardt, TerminationReason,
};
use crate::standardize::Standardizer;

use super::gauss_newton::{
    HiddenLayerProducts, by_structure, entries_per_sample, gram_products, same_bits,
};
use super::held_out::{BestHeldOut, out_of_time};
use super::network::{
    FittedMlp, MAX_WIDTH, Problem, RestartReport, initial_parameters, parameter_count,
};
use super::params::{Mlp, MlpParams, Trainer};

/// The largest Jacobian (residuals x weights) Levenberg-Marquardt takes
/// under [`Trainer::Auto`]: beyond it each iteration's products cost more
/// than Adam's whole run.
const MAX_JACOBIAN_ENTRIES: usize = 20_000_000;
/// The most weights Levenberg-Marquardt takes under [`Trainer::Auto`].
const MAX_LM_WEIGHTS: usize = 1000;
/// The Jacobian entries Levenberg-Marquardt's curvature is formed from
/// under [`Trainer::Auto`] (the first training rows; its gradient and its
/// steps' acceptance take every row): a sample of this size steers the
/// steps as well as the largest Jacobian does, at a fraction of each
/// iteration's cost.
const MAX_CURVATURE_ENTRIES: usize = 8_000_000;

/// The entries of Levenberg-Marquardt's products under [`Trainer::Auto`]:
/// the most before Adam runs beside it, and the sample its curvature is
/// formed from on more rows than that sample.
#[derive(Debug, Clone, Copy)]
struct Limits {
    jacobian: usize,
    curvature: usize,
}

/// The limits every fit runs under (a test may lower them to reach the
/// large charts' paths on small data).
const LIMITS: Limits = Limits {
    jacobian: MAX_JACOBIAN_ENTRIES,
    curvature: MAX_CURVATURE_ENTRIES,
};

/// How the restarts of one fit are trained.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Plan {
    /// Every restart by Levenberg-Marquardt on every training row.
    LevenbergMarquardt,
    /// Every restart by Adam, or by L-BFGS where the trainer says so.
    Adam,
    /// [`Trainer::Auto`] on more rows than Levenberg-Marquardt's products
    /// take: its restarts on every training row, their curvature from a
    /// sample of the rows (on the first `lm_rows` where the products come
    /// from the network's structure), as many by Adam on every row, the
    /// lowest held-out error winning.
    Both {
        /// The rows Levenberg-Marquardt's products take whole: its
        /// restarts' rows where the products come from the network's
        /// structure.
        lm_rows: usize,
    },
}

/// The plan for `trainer` on `rows` training samples for a network of
/// layer sizes `sizes`, Levenberg-Marquardt's products keeping at most
/// `max_jacobian` entries.
fn plan(trainer: Trainer, rows: usize, sizes: &[usize], max_jacobian: usize) -> Plan {
    match trainer {
        Trainer::LevenbergMarquardt => Plan::LevenbergMarquardt,
        Trainer::Adam { .. } | Trainer::Lbfgs { .. } => Plan::Adam,
        Trainer::Auto if parameter_count(sizes) > MAX_LM_WEIGHTS => Plan::Adam,
        Trainer::Auto => {
            let lm_rows = max_jacobian / entries_per_sample(sizes).max(1);
            if rows <= lm_rows {
                Plan::LevenbergMarquardt
            } else {
                Plan::Both { lm_rows }
            }
        }
    }
}

/// Where a fit begins: anew, from a fit's networks ([`Mlp::fit_from`]), or
/// beside a fit's members with this many more ([`Mlp::fit_more`]).
#[derive(Clone, Copy)]
enum Begin<'a> {
    Anew,
    Further(&'a FittedMlp),
    More(&'a FittedMlp, usize),
}

/// The rows of `m` in the order the training takes them, the first
/// `n_held` (the second value) held out: a shuffle seeded by the
/// network's seed, so a network and a density of one seed hold out the
/// same rows.
///
/// # Errors
/// Too few rows for two training rows and, where a fraction is held out,
/// one held-out row.
pub(super) fn held_out_split(m: usize, p: &MlpParams) -> Result<(Vec<usize>, usize)> {
    let n_held = (p.validation_fraction * m as f64).round() as usize;
    let n_train = m - n_held;
    if n_train < 2 || (p.validation_fraction > 0.0 && n_held == 0) {
        return Err(FitError::TooFewSamples {
            got: m,
            needed: 2 + usize::from(p.validation_fraction > 0.0),
            why: "training and held-out sets both need samples".into(),
        });
    }
    let mut order: Vec<usize> = (0..m).collect();
    let mut split_rng = ChaCha8Rng::seed_from_u64(p.seed ^ 0x5350_4c49_5400);
    order.shuffle(&mut split_rng);
    Ok((order, n_held))
}

/// The restart of the lowest held-out loss; ties go to the lower index, so
/// the choice does not depend on scheduling.
fn lowest_held_out(reports: &[RestartReport]) -> usize {
    reports
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.validation_mse.total_cmp(&b.1.validation_mse))
        .map_or(0, |(i, _)| i)
}

fn train_one(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    levenberg_marquardt: bool,
) -> (Vec<f64>, RestartReport) {
    let mut rng = restart_rng(mlp, restart);
    let params = initial_parameters(problem.sizes, &mut rng);
    train_with(problem, mlp, restart, params, &mut rng, levenberg_marquardt)
}

/// One restart from given weights (a fit continued from an earlier one),
/// Adam's batches drawn from the restart's own stream.
fn train_from(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    params: Vec<f64>,
    levenberg_marquardt: bool,
) -> (Vec<f64>, RestartReport) {
    train_with(
        problem,
        mlp,
        restart,
        params,
        &mut restart_rng(mlp, restart),
        levenberg_marquardt,
    )
}

/// The stream of restart `restart`: its initial weights, then Adam's
/// batches.
pub(super) fn restart_rng(mlp: &MlpParams, restart: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(mlp.seed ^ 0x4d4c_5000);
    rng.set_stream(restart as u64 + 1);
    rng
}

/// One restart from `params` by either trainer.
fn train_with(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    params: Vec<f64>,
    rng: &mut ChaCha8Rng,
    levenberg_marquardt: bool,
) -> (Vec<f64>, RestartReport) {
    if levenberg_marquardt {
        train_levenberg_marquardt(problem, mlp, restart, params)
    } else if let Trainer::Lbfgs { iterations } = mlp.trainer {
        super::lbfgs::train_lbfgs(problem, mlp, restart, params, iterations)
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
            rng,
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
    let n = problem.n_params();
    let mut grad = vec![0.0; n];
    let mut adam = crate::adam::Adam::new(n, learning_rate);
    let (mut best, held_out) = BestHeldOut::start(problem, &params, mlp.patience);
    let mut order = problem.train.to_vec();
    let mut done = 0;
    let mut reason = TerminationReason::MaxEpochs;
    for _ in 0..epochs {
        done += 1;
        order.shuffle(rng);
        for batch in order.chunks(batch_size) {
            problem.gradient(&params, batch, &mut grad);
            adam.step(&mut params, &grad);
        }
        let held = problem.mse(&params, held_out);
        if best.observe(held, &params) {
            reason = TerminationReason::EpochsWithoutImprovement;
            break;
        }
        if out_of_time(mlp) {
            reason = TerminationReason::EpochsUntilDeadline;
            break;
        }
    }
    best.into_restart(problem, restart, done, reason)
}

fn train_levenberg_marquardt(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    params: Vec<f64>,
) -> (Vec<f64>, RestartReport) {
    let (mut best, held_out) = BestHeldOut::start(problem, &params, mlp.patience);
    let mut least_squares = NetworkLeastSquares::new(problem);
    let solver = LevenbergMarquardt::new()
        .max_iterations(mlp.max_iterations)
        .tolerance(1e-12)
        .damping(Damping::Identity)
        .initial_damping(1e-3)
        .max_damping(1e10);
    let mut timed_out = false;
    let Ok(minimum) = solver.minimize(&mut least_squares, &params, |iterate| {
        let held = problem.mse(iterate.x, held_out);
        if best.observe(held, iterate.x) {
            ControlFlow::Break(())
        } else if out_of_time(mlp) {
            timed_out = true;
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    let reason = if timed_out {
        TerminationReason::Deadline
    } else {
        minimum.reason
    };
    best.into_restart(problem, restart, minimum.iterations, reason)
}

/// The training rows' residuals as a least-squares problem: the cost is
/// the mean squared error per target value plus the weight decay over the
/// same count, and the Gauss-Newton products come from the back-propagated
/// Jacobian (kept here between iterations, transposed: parameters x rows)
/// or, for a network of one hidden layer and several targets, from its
/// structure.
struct NetworkLeastSquares<'p, 'a> {
    problem: &'p Problem<'a>,
    rows: usize,
    products: Products,
}

/// How a restart computes its Gauss-Newton products, with its scratch.
enum Products {
    ByJacobian {
        jt: Vec<f64>,
        res: Vec<f64>,
        jtj: Mat<f64>,
        jtr: Mat<f64>,
        /// Every training sample's activations where the residuals were
        /// last evaluated, and the weights there: the accepted step's, so
        /// its Jacobian needs no forward pass.
        kept: Vec<f64>,
        kept_at: Option<Vec<f64>>,
    },
    ByStructure(Box<HiddenLayerProducts>),
}

impl<'p, 'a> NetworkLeastSquares<'p, 'a> {
    fn new(problem: &'p Problem<'a>) -> Self {
        let n = problem.n_params();
        let q = *problem.sizes.last().unwrap_or(&1);
        let rows = problem.train.len() * q;
        let products = if by_structure(problem.sizes) {
            Products::ByStructure(Box::new(HiddenLayerProducts::new(problem)))
        } else {
            let sampled = problem.curvature_rows.unwrap_or(problem.train.len()) * q;
            Products::ByJacobian {
                jt: vec![0.0; n * sampled],
                res: vec![0.0; sampled],
                jtj: Mat::zeros(n, n),
                jtr: Mat::zeros(n, 1),
                kept: vec![0.0; problem.train.len() * problem.activations_per_sample()],
                kept_at: None,
            }
        };
        Self {
            problem,
            rows,
            products,
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
        r.resize(self.rows, 0.0);
        match &mut self.products {
            // The structure's terms come with the residuals: kept, they
            // spare the accepted point's products a second forward pass.
            Products::ByStructure(products) => products.evaluate(self.problem, params, r),
            Products::ByJacobian { kept, kept_at, .. } => {
                self.problem.residuals_keeping(params, r, Some(kept));
                let at = kept_at.get_or_insert_with(Vec::new);
                at.clear();
                at.extend_from_slice(params);
            }
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
        match &mut self.products {
            Products::ByJacobian {
                jt,
                res,
                jtj: gram,
                jtr: gradient,
                kept,
                kept_at,
            } => {
                let here = kept_at.as_deref().is_some_and(|at| same_bits(at, params));
                match self.problem.curvature_rows {
                    None => {
                        self.problem
                            .jacobian(params, jt, res, here.then_some(kept.as_slice()));
                        gram_products(jt, res, scale, gram, gradient);
                        for i in 0..n {
                            for j in 0..=i {
                                jtj[i * n + j] = gram[(i, j)];
                            }
                            jtr[i] = gradient[(i, 0)];
                        }
                    }
                    Some(rows) => {
                        // The curvature of the first rows, scaled as a mean
                        // like the whole; the gradient of every row, whose
                        // half is J'r / rows with the decay's term in it.
                        let sample = Problem {
                            train: &self.problem.train[..rows],
                            offsets: self.problem.offsets.clone(),
                            ..*self.problem
                        };
                        let width = self.problem.activations_per_sample();
                        let kept = here.then(|| &kept[..rows * width]);
                        sample.jacobian(params, jt, res, kept);
                        let q = *self.problem.sizes.last().unwrap_or(&1);
                        gram_products(jt, res, 1.0 / (rows * q) as f64, gram, gradient);
                        for i in 0..n {
                            for j in 0..=i {
                                jtj[i * n + j] = gram[(i, j)];
                            }
                        }
                        self.problem.gradient(params, self.problem.train, jtr);
                        for (g, p) in jtr.iter_mut().zip(params) {
                            // The decay's gradient is added below.
                            *g = 0.5 * *g - self.problem.decay * scale * p;
                        }
                    }
                }
            }
            Products::ByStructure(products) => {
                products.products(self.problem, params, scale, jtj, jtr);
            }
        }
        // The weight decay term decay * ||p||^2 / rows: its Hessian and gradient.
        let d = self.problem.decay * scale;
        for i in 0..n {
            jtj[i * n + i] += d;
            jtr[i] += d * params[i];
        }
        Ok(())
    }
}

impl Regressor for Mlp {
    type Model = FittedMlp;

    fn fit(&self, x: ArrayView2<'_, f64>, y: ArrayView2<'_, f64>) -> Result<FittedMlp> {
        self.fit_within(x, y, LIMITS, Begin::Anew)
    }
}

impl Mlp {
    /// Train `start` further on `x` and `y` (typically more rows than it
    /// was fitted on): each of its networks (the kept one, or every member
    /// of an ensemble) is one restart that starts from its weights, with
    /// `start`'s scaling of features and targets, by the trainer this
    /// network's settings choose for these rows, on a held-out split of
    /// these rows. A restart keeps its best held-out weights, the start's
    /// among them, so the result is never worse than `start` on the
    /// held-out rows, however early [`Mlp::stopped_by`] stops it: a fit that
    /// can be cut short at any time.
    ///
    /// ```
    /// use ndarray::Array2;
    /// use twostage_fit::{MlpParams, Predictor, Regressor};
    ///
    /// let x = Array2::from_shape_fn((800, 1), |(i, _)| i as f64 / 400.0 - 1.0);
    /// let y = x.mapv(|v| (3.0 * v).sin());
    /// let net = MlpParams::new(&[8])?.seed(3).check()?;
    /// let rows = ndarray::s![..100, ..];
    /// let start = net.fit(x.slice(rows), y.slice(rows))?;
    /// let further = net.fit_from(&start, x.view(), y.view())?;
    /// let mse = |f: &twostage_fit::FittedMlp| -> Result<f64, twostage_fit::FitError> {
    ///     let p = f.predict(x.view())?;
    ///     Ok((&p - &y).mapv(|e| e * e).mean().unwrap_or(f64::NAN))
    /// };
    /// assert!(mse(&further)? <= mse(&start)?);
    /// # Ok::<(), twostage_fit::FitError>(())
    /// ```
    ///
    /// # Errors
    /// A `start` of other layer sizes, or what a fit reports.
    pub fn fit_from(
        &self,
        start: &FittedMlp,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
    ) -> Result<FittedMlp> {
        self.fit_within(x, y, LIMITS, Begin::Further(start))
    }

    /// The ensemble `fitted` (a fit of this network on `x` and `y`) with
    /// `more` members trained anew beside its own: the restarts that follow
    /// its last, each from its own seed stream, on the same held-out split
    /// and with `fitted`'s scaling. With the same data and no stop time,
    /// the result is the bits of a fit with that many more restarts at
    /// once, so a fit that grows while time is left can be written down as
    /// a number of members. A member that [`Mlp::stopped_by`] cut short is
    /// left out: trained part of the way, it would pull the average.
    ///
    /// ```
    /// use ndarray::Array2;
    /// use twostage_fit::{MlpParams, Regressor};
    ///
    /// let x = Array2::from_shape_fn((300, 1), |(i, _)| i as f64 / 150.0 - 1.0);
    /// let y = x.mapv(|v| (3.0 * v).sin());
    /// let four = MlpParams::new(&[6])?.ensemble(true).seed(2).check()?;
    /// let six = MlpParams::new(&[6])?.ensemble(true).seed(2).restarts(6).check()?;
    /// let grown = four.fit_more(&four.fit(x.view(), y.view())?, x.view(), y.view(), 2)?;
    /// assert_eq!(grown.n_members(), 6);
    /// assert_eq!(grown, six.fit(x.view(), y.view())?);
    /// # Ok::<(), twostage_fit::FitError>(())
    /// ```
    ///
    /// # Errors
    /// A network that is not an ensemble, a `fitted` of other layer sizes,
    /// or what a fit reports.
    pub fn fit_more(
        &self,
        fitted: &FittedMlp,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
        more: usize,
    ) -> Result<FittedMlp> {
        if !self.params.ensemble {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "ensemble",
                value: "false".into(),
                reason: "only an ensemble averages members: set MlpParams::ensemble".into(),
            }));
        }
        self.fit_within(x, y, LIMITS, Begin::More(fitted, more))
    }

    /// [`Regressor::fit`] with Levenberg-Marquardt's products under
    /// `limits` ([`Trainer::Auto`]), from scratch, further
    /// from a start ([`Mlp::fit_from`]) or with more members
    /// ([`Mlp::fit_more`]).
    fn fit_within(
        &self,
        x: ArrayView2<'_, f64>,
        y: ArrayView2<'_, f64>,
        limits: Limits,
        begin: Begin<'_>,
    ) -> Result<FittedMlp> {
        let (start, grown) = match begin {
            Begin::Anew => (None, None),
            Begin::Further(start) => (Some(start), None),
            Begin::More(fitted, more) => (Some(fitted), Some((fitted, more))),
        };
        check::training_data(x, y)?;
        let p = &self.params;
        let (m, n_in) = x.dim();
        let q = y.ncols();
        if n_in > MAX_WIDTH || q > MAX_WIDTH {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "features or targets",
                value: format!("{n_in} features, {q} targets"),
                reason: "at most 256 each".into(),
            }));
        }
        let mut sizes = vec![n_in];
        sizes.extend(&p.hidden);
        sizes.push(q);
        let (order, n_held) = held_out_split(m, p)?;
        if let Some(start) = start
            && start.sizes != sizes
        {
            return Err(FitError::InvalidSetting(InvalidSetting {
                name: "start",
                value: format!("layer sizes {:?}", start.sizes),
                reason: format!("this network and these data have layer sizes {sizes:?}"),
            }));
        }
        let (features, targets) = match start {
            Some(start) => (start.features.clone(), start.targets.clone()),
            None => (Standardizer::fit(x), Standardizer::fit(y)),
        };
        // Standard layout so rows are contiguous slices.
        let xs = features.transform(x).as_standard_layout().to_owned();
        let ts = targets.transform(y);
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
            curvature_rows: None,
        };
        let plan = plan(p.trainer, train.len(), &sizes, limits.jacobian);
        // Levenberg-Marquardt's problem under `Trainer::Auto`: on more rows
        // than its curvature's sample, every row with the curvature of the
        // sample where the products come from the Jacobian; where they come
        // from the structure, the rows its products take.
        let curvature =
            (limits.curvature / entries_per_sample(&sizes).max(1)).clamp(2, train.len());
        let sampled =
            p.trainer == Trainer::Auto && !by_structure(&sizes) && train.len() > curvature;
        let lm_problem = match plan {
            Plan::Both { .. } | Plan::LevenbergMarquardt if sampled => Problem {
                curvature_rows: Some(curvature),
                offsets: problem.offsets.clone(),
                ..problem
            },
            Plan::Both { lm_rows } => Problem {
                train: &train[..lm_rows.clamp(2, train.len())],
                offsets: problem.offsets.clone(),
                ..problem
            },
            _ => Problem {
                offsets: problem.offsets.clone(),
                ..problem
            },
        };
        // Restart r < restarts as the plan says first; in `Both`, restarts
        // r >= restarts by Adam (seed streams of their own).
        let anew = |r: usize| match plan {
            Plan::Both { .. } if r < p.restarts => train_one(&lm_problem, p, r, true),
            Plan::LevenbergMarquardt => train_one(&lm_problem, p, r, true),
            _ => train_one(&problem, p, r, false),
        };
        if let Some((fitted, more)) = grown {
            let first = fitted.reports.len();
            let runs: Vec<(Vec<f64>, RestartReport)> =
                (first..first + more).into_par_iter().map(anew).collect();
            let mut grown = fitted.clone();
            for (weights, report) in runs {
                if !report.reason.is_deadline() {
                    grown.members.push(weights);
                    grown.reports.push(report);
                }
            }
            grown.best = lowest_held_out(&grown.reports);
            return Ok(grown);
        }
        let runs: Vec<(Vec<f64>, RestartReport)> = match (start, plan) {
            // Further from a start: its networks, by LM (on the rows LM
            // takes) unless the plan is Adam alone.
            (Some(start), _) => start
                .members
                .par_iter()
                .enumerate()
                .map(|(r, weights)| {
                    train_from(&lm_problem, p, r, weights.clone(), plan != Plan::Adam)
                })
                .collect(),
            (None, Plan::LevenbergMarquardt | Plan::Adam) => {
                (0..p.restarts).into_par_iter().map(anew).collect()
            }
            (None, Plan::Both { .. }) => (0..2 * p.restarts).into_par_iter().map(anew).collect(),
        };
        let (members, reports): (Vec<Vec<f64>>, Vec<RestartReport>) = runs.into_iter().unzip();
        let best = lowest_held_out(&reports);
        let members = if p.ensemble || start.is_some() {
            // A start's networks were its members: each continued is one.
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

#[cfg(test)]
mod tests;
