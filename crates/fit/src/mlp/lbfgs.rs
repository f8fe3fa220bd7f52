//! L-BFGS on the whole training set (Nocedal and Wright, Numerical
//! Optimization, 2nd ed., 2006: the two-loop recursion, Algorithm 7.4, and
//! Algorithm 7.5 with a backtracking line search under the Armijo
//! condition): each iteration one gradient of every training row and a
//! few of their losses, against Levenberg-Marquardt's products of a
//! Jacobian of rows x weights. Where the rows and the weights are many,
//! an iteration costs a small fraction of one of Levenberg-Marquardt's.

use std::collections::VecDeque;

use crate::levenberg_marquardt::TerminationReason;

use super::held_out::BestHeldOut;
use super::network::{Problem, RestartReport};
use super::params::MlpParams;

/// Curvature pairs kept (the memory m of Nocedal and Wright; 3 to 20
/// work in practice, their section 7.2).
const MEMORY: usize = 10;
/// The Armijo condition's sufficient-decrease constant.
const ARMIJO: f64 = 1e-4;
/// Halvings of the step before an iteration gives up.
const HALVINGS: usize = 40;
/// The cost's relative decrease below which an iteration counts as none.
const TOLERANCE: f64 = 1e-12;
/// Iterations per unit of `patience`: an L-BFGS iteration moves the
/// weights far less than a Levenberg-Marquardt one, whose count the
/// patience was set for.
pub(super) const PATIENCE_SCALE: usize = 20;

/// The training loss L-BFGS minimizes: the mean squared error per target
/// value over the training rows plus the weight decay, the cost whose
/// gradient [`Problem::gradient`] gives.
fn loss(problem: &Problem<'_>, params: &[f64]) -> f64 {
    let q = *problem.sizes.last().unwrap_or(&1);
    let values = (problem.train.len() * q).max(1) as f64;
    problem.mse(params, problem.train) + problem.penalty(params) / values
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The direction `-H g` of the two-loop recursion over the kept pairs
/// `(s, y, 1 / y's)`, oldest first, the initial matrix scaled by the
/// newest pair (Nocedal and Wright, eq. 7.20).
fn direction(grad: &[f64], pairs: &VecDeque<(Vec<f64>, Vec<f64>, f64)>) -> Vec<f64> {
    let mut d: Vec<f64> = grad.iter().map(|g| -g).collect();
    let mut alphas = Vec::with_capacity(pairs.len());
    for (s, y, rho) in pairs.iter().rev() {
        let alpha = rho * dot(s, &d);
        for (d, y) in d.iter_mut().zip(y) {
            *d -= alpha * y;
        }
        alphas.push(alpha);
    }
    if let Some((s, y, _)) = pairs.back() {
        let gamma = dot(s, y) / dot(y, y);
        for d in &mut d {
            *d *= gamma;
        }
    }
    for ((s, y, rho), alpha) in pairs.iter().zip(alphas.iter().rev()) {
        let beta = rho * dot(y, &d);
        for (d, s) in d.iter_mut().zip(s) {
            *d += (alpha - beta) * s;
        }
    }
    d
}

/// What L-BFGS minimizes, and the held-out loss it watches.
pub(crate) trait Objective {
    /// The training loss at `params`.
    fn loss(&self, params: &[f64]) -> f64;
    /// The training loss's gradient at `params`, into `grad`.
    fn gradient(&self, params: &[f64], grad: &mut [f64]);
    /// The loss on the rows held out to stop by.
    fn held_out(&self, params: &[f64]) -> f64;
}

/// The network's mean squared error, as [`Problem`] gives it.
struct MeanSquares<'p, 'a> {
    problem: &'p Problem<'a>,
    held_out: &'p [usize],
}

impl Objective for MeanSquares<'_, '_> {
    fn loss(&self, params: &[f64]) -> f64 {
        loss(self.problem, params)
    }

    fn gradient(&self, params: &[f64], grad: &mut [f64]) {
        self.problem.gradient(params, self.problem.train, grad);
    }

    fn held_out(&self, params: &[f64]) -> f64 {
        self.problem.mse(params, self.held_out)
    }
}

/// One restart from `params` by L-BFGS, at most `iterations` iterations,
/// keeping the weights of the lowest held-out loss (checked every
/// iteration, `patience` counting [`PATIENCE_SCALE`] iterations) and
/// stopping at the
/// training's deadline.
pub(super) fn train_lbfgs(
    problem: &Problem<'_>,
    mlp: &MlpParams,
    restart: usize,
    params: Vec<f64>,
    iterations: usize,
) -> (Vec<f64>, RestartReport) {
    let (mut best, held_out) = super::held_out::BestHeldOut::start(
        problem,
        &params,
        mlp.patience.saturating_mul(PATIENCE_SCALE),
    );
    let objective = MeanSquares { problem, held_out };
    let (done, reason) = minimize(&objective, params, iterations, &mut best, mlp.stop_by);
    best.into_restart(problem, restart, done, reason)
}

/// L-BFGS from `params`, at most `iterations` iterations, `best` watching
/// the held-out loss after each (it keeps the weights to return and says
/// when patience has run out), stopping at `stop_by`: the iterations run
/// and why they stopped.
pub(crate) fn minimize(
    objective: &impl Objective,
    mut params: Vec<f64>,
    iterations: usize,
    best: &mut BestHeldOut,
    stop_by: Option<std::time::Instant>,
) -> (usize, TerminationReason) {
    let n = params.len();
    let mut grad = vec![0.0; n];
    objective.gradient(&params, &mut grad);
    let mut cost = objective.loss(&params);
    let mut pairs: VecDeque<(Vec<f64>, Vec<f64>, f64)> = VecDeque::with_capacity(MEMORY);
    let mut reason = TerminationReason::LbfgsMaxIterations;
    let mut done = 0;
    let mut trial = vec![0.0; n];
    let mut trial_grad = vec![0.0; n];
    while done < iterations {
        done += 1;
        let mut d = direction(&grad, &pairs);
        let mut slope = dot(&grad, &d);
        if slope >= 0.0 || slope.is_nan() {
            // Not a descent direction (curvature pairs gone stale): start
            // the memory again from the steepest descent.
            pairs.clear();
            d = grad.iter().map(|g| -g).collect();
            slope = dot(&grad, &d);
        }
        // The first step, without curvature, moves the weights by at most
        // one unit; later ones try the quasi-Newton step itself.
        let mut step = if pairs.is_empty() {
            1.0 / d.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1.0)
        } else {
            1.0
        };
        let mut accepted = None;
        for _ in 0..HALVINGS {
            for ((t, p), d) in trial.iter_mut().zip(&params).zip(&d) {
                *t = p + step * d;
            }
            let trial_cost = objective.loss(&trial);
            if trial_cost.is_finite() && trial_cost <= cost + ARMIJO * step * slope {
                accepted = Some(trial_cost);
                break;
            }
            step *= 0.5;
        }
        let Some(new_cost) = accepted else {
            reason = TerminationReason::LbfgsConverged;
            break;
        };
        objective.gradient(&trial, &mut trial_grad);
        let s: Vec<f64> = trial.iter().zip(&params).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = trial_grad.iter().zip(&grad).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        // A pair of no positive curvature would spoil the recursion.
        if sy > f64::EPSILON * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
            if pairs.len() == MEMORY {
                pairs.pop_front();
            }
            pairs.push_back((s, y, 1.0 / sy));
        }
        std::mem::swap(&mut params, &mut trial);
        std::mem::swap(&mut grad, &mut trial_grad);
        let decrease = (cost - new_cost) / cost.abs().max(f64::MIN_POSITIVE);
        cost = new_cost;
        if best.observe(objective.held_out(&params), &params) {
            reason = TerminationReason::LbfgsWithoutImprovement;
            break;
        }
        if decrease < TOLERANCE && pairs.len() == MEMORY {
            reason = TerminationReason::LbfgsConverged;
            break;
        }
        if super::held_out::past(stop_by) {
            reason = TerminationReason::LbfgsUntilDeadline;
            break;
        }
    }
    (done, reason)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a convex quadratic 1/2 x'Ax - b'x, curvature pairs of
    /// A-conjugate steps make the recursion's matrix A^-1 (the hereditary
    /// property of BFGS on quadratics, Nocedal and Wright, Theorem 6.4), so
    /// its step from any point lands on the minimizer A^-1 b.
    #[test]
    fn the_two_loop_recursion_inverts_a_quadratic_s_curvature() {
        // A = [[4, 1], [1, 3]], b = (1, 2): x* = A^-1 b = (1/11, 7/11).
        let a = [[4.0, 1.0], [1.0, 3.0]];
        let grad_at = |x: &[f64]| -> Vec<f64> {
            vec![
                a[0][0] * x[0] + a[0][1] * x[1] - 1.0,
                a[1][0] * x[0] + a[1][1] * x[1] - 2.0,
            ]
        };
        let mut pairs = VecDeque::new();
        // (1, 0) and (1, -4) are A-conjugate: 4 - 4 = 0.
        for s in [vec![1.0, 0.0], vec![1.0, -4.0]] {
            let y = vec![
                a[0][0] * s[0] + a[0][1] * s[1],
                a[1][0] * s[0] + a[1][1] * s[1],
            ];
            let rho = 1.0 / dot(&s, &y);
            pairs.push_back((s, y, rho));
        }
        let x0 = [0.0, 0.0];
        let d = direction(&grad_at(&x0), &pairs);
        assert!((d[0] - 1.0 / 11.0).abs() < 1e-14, "{d:?}");
        assert!((d[1] - 7.0 / 11.0).abs() < 1e-14, "{d:?}");
    }

    /// Without pairs the direction is the steepest descent.
    #[test]
    fn without_memory_the_direction_is_minus_the_gradient() {
        assert_eq!(direction(&[0.5, -2.0], &VecDeque::new()), vec![-0.5, 2.0]);
    }
}
