//! One Levenberg-Marquardt solver for every nonlinear least-squares fit of
//! the project: the network's training, prediction error, indirect
//! inference and the refinement of a two-stage estimate.
//!
//! A problem says how to compute its residuals (the one required method)
//! and may supply its own cost scaling, Gauss-Newton products and
//! feasible set; the solver owns the damping schedule, the acceptance test
//! and the stop rules, and reports why it stopped with the same
//! [`TerminationReason`] for everyone.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

mod differences;
mod run;

pub use differences::{CentralDifferences, ForwardDifferences};
pub use run::{Evaluation, LmRun, ModelAt, Need};

/// Why an iterative fit stopped.
///
/// Stored in estimator files (a network's restart reports): new variants go
/// at the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum TerminationReason {
    /// The observer asked to stop: the held-out loss did not improve for
    /// `patience` checks.
    EarlyStopping,
    /// The iteration budget ran out.
    MaxIterations,
    /// No step reduced the cost even with the largest damping: a minimum
    /// (or a point the problem's Gauss-Newton model cannot leave).
    DampingLimit,
    /// The relative decrease of the cost fell below the tolerance.
    Converged,
    /// Adam's epoch budget ran out.
    MaxEpochs,
    /// Adam's held-out loss did not improve for `patience` epochs (before
    /// this variant, Adam said [`Self::EarlyStopping`]).
    EpochsWithoutImprovement,
    /// An evaluation of the model failed during the run (a simulation that
    /// broke off, say): the last accepted point is the answer.
    EvaluationFailed,
    /// Levenberg-Marquardt's iterations ran until the training's time was
    /// up (`Mlp::stopped_by`): the best weights so far are the answer.
    Deadline,
    /// Adam's epochs ran until the training's time was up: the best
    /// weights so far are the answer.
    EpochsUntilDeadline,
    /// A descent among several came where another of the same search
    /// already stood at no higher cost: from there it would follow the
    /// other's path, so it stops and the other goes on.
    Joined,
    /// A descent among several stood far above the best of its search and
    /// was making little progress: it would not come near the best fit
    /// within its budget, so it stopped where it stood.
    Outpaced,
    /// L-BFGS's iteration budget ran out.
    LbfgsMaxIterations,
    /// L-BFGS's held-out loss did not improve for `patience` iterations.
    LbfgsWithoutImprovement,
    /// L-BFGS found no step that decreases the loss enough, or its
    /// decrease fell below the tolerance.
    LbfgsConverged,
    /// L-BFGS's iterations ran until the training's time was up: the best
    /// weights so far are the answer.
    LbfgsUntilDeadline,
}

impl TerminationReason {
    /// The reason's name as tables and reports write it. Stable: a variant
    /// renamed in the code keeps its name here, so files written before
    /// still read the same.
    pub fn name(self) -> &'static str {
        match self {
            Self::EarlyStopping => "EarlyStopping",
            Self::MaxIterations => "MaxIterations",
            Self::DampingLimit => "DampingLimit",
            Self::Converged => "Converged",
            Self::MaxEpochs => "MaxEpochs",
            Self::EpochsWithoutImprovement => "EpochsWithoutImprovement",
            Self::EvaluationFailed => "EvaluationFailed",
            Self::Deadline => "Deadline",
            Self::EpochsUntilDeadline => "EpochsUntilDeadline",
            Self::Joined => "Joined",
            Self::Outpaced => "Outpaced",
            Self::LbfgsMaxIterations => "LbfgsMaxIterations",
            Self::LbfgsWithoutImprovement => "LbfgsWithoutImprovement",
            Self::LbfgsConverged => "LbfgsConverged",
            Self::LbfgsUntilDeadline => "LbfgsUntilDeadline",
        }
    }

    /// Whether the training's time ran out before the trainer's own end.
    pub fn is_deadline(self) -> bool {
        matches!(
            self,
            Self::Deadline | Self::EpochsUntilDeadline | Self::LbfgsUntilDeadline
        )
    }

    /// The trainer that stops for this reason: Adam's and L-BFGS's reasons
    /// are their own.
    pub fn trainer(self) -> &'static str {
        match self {
            Self::MaxEpochs | Self::EpochsWithoutImprovement | Self::EpochsUntilDeadline => "Adam",
            Self::LbfgsMaxIterations
            | Self::LbfgsWithoutImprovement
            | Self::LbfgsConverged
            | Self::LbfgsUntilDeadline => "L-BFGS",
            _ => "Levenberg-Marquardt",
        }
    }
}

/// A nonlinear least-squares problem: minimize the cost of the residuals
/// `r(x)` over `x`.
///
/// Only [`LeastSquaresProblem::residuals`] is required. The methods take
/// `&mut self` so that a problem can keep its scratch space (a network's
/// Jacobian is rows x parameters) across the solver's calls.
pub trait LeastSquaresProblem {
    /// What a failed evaluation returns.
    type Error;

    /// The residuals at `x`, written into `r` (resized as the problem needs).
    ///
    /// # Errors
    /// Whatever the problem cannot evaluate; the solver passes it on.
    fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), Self::Error>;

    /// The cost of residuals `r` at `x` (default: `sum r_i^2`). A problem
    /// that scales its cost or adds a penalty scales [`Self::gauss_newton`]
    /// the same way.
    fn cost(&mut self, x: &[f64], r: &[f64]) -> f64 {
        let _ = x;
        r.iter().map(|v| v * v).sum()
    }

    /// The Gauss-Newton model at `x`, whose residuals are `r`: `J'J` into
    /// `jtj` (row-major n x n; the solver reads its lower triangle) and the
    /// gradient half `J'r` into `jtr`. Default: central differences of the
    /// residuals with steps `1e-6 max(1, |x_j|)`, shifted inward at the
    /// faces of [`Self::domain`] and divided by the step actually taken;
    /// sums in index order.
    ///
    /// # Errors
    /// As [`Self::residuals`].
    fn gauss_newton(
        &mut self,
        x: &[f64],
        r: &[f64],
        jtj: &mut [f64],
        jtr: &mut [f64],
    ) -> Result<(), Self::Error> {
        let (differences, points) = CentralDifferences::at(x, self.domain());
        let mut values = vec![Vec::new(); points.len()];
        for (point, value) in points.iter().zip(&mut values) {
            self.residuals(point, value)?;
        }
        differences.products(&values, r, jtj, jtr);
        Ok(())
    }

    /// Where the residuals are defined, as lower and upper bounds per
    /// parameter (default: everywhere). Finite differences never step
    /// outside it.
    fn domain(&self) -> Option<(&[f64], &[f64])> {
        None
    }

    /// Move `x` into the feasible set (default: everything is feasible).
    /// Trial points are projected before they are evaluated.
    fn project(&self, x: &mut [f64]) {
        let _ = x;
    }
}

/// `J'J` and `J'r` from the columns of `J` (each `r.len()` long, stored one
/// after another), with sums in index order.
pub fn normal_products(columns: &[f64], r: &[f64], jtj: &mut [f64], jtr: &mut [f64]) {
    let rows = r.len().max(1);
    let n = jtr.len();
    for a in 0..n {
        let ca = &columns[a * rows..(a + 1) * rows];
        for b in 0..n {
            let cb = &columns[b * rows..(b + 1) * rows];
            jtj[a * n + b] = ca.iter().zip(cb).map(|(x, y)| x * y).sum();
        }
        jtr[a] = ca.iter().zip(r).map(|(x, y)| x * y).sum();
    }
}

/// How the damping enters the step equations `(J'J + D) step = -J'r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Damping {
    /// Levenberg's `D = mu I`: for parameters of one scale (a standardized
    /// network's weights).
    Identity,
    /// Marquardt's `D = mu (diag(J'J) + floor)`: invariant to the
    /// parameters' scales; `floor` keeps a parameter with no gradient
    /// damped.
    Diagonal {
        /// Added to each diagonal entry before scaling.
        floor: f64,
    },
}

/// One accepted iterate, shown to the observer.
#[derive(Debug, Clone, Copy)]
pub struct Iterate<'a> {
    /// Iterations so far (this one included).
    pub iteration: usize,
    /// The accepted point.
    pub x: &'a [f64],
    /// Its cost.
    pub cost: f64,
    /// The damping that will start the next iteration.
    pub damping: f64,
}

/// Where a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// The last accepted point.
    pub x: Vec<f64>,
    /// Its cost.
    pub cost: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// Why it stopped.
    pub reason: TerminationReason,
}

/// The Levenberg-Marquardt solver's settings.
///
/// | setting | default | valid |
/// |---|---|---|
/// | `max_iterations` | 100 | >= 1 (0 returns the start) |
/// | `tolerance` (relative cost decrease that counts as converged) | 1e-12 | >= 0 |
/// | `damping` | [`Damping::Identity`] | |
/// | `initial_damping` | 1e-3 | > 0 |
/// | `max_damping` (steps are tried while the damping is at most this) | 1e10 | > 0 |
/// | `min_damping` | 1e-12 | > 0 |
///
/// After an accepted step the damping is divided by 10 (not below
/// `min_damping`); after a refused one, or a damped matrix that is not
/// positive definite, multiplied by 10.
///
/// ```
/// use twostage_fit::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
/// // Rosenbrock as least squares: r = (10 (x1 - x0^2), 1 - x0), minimum at (1, 1).
/// struct Rosenbrock;
/// impl LeastSquaresProblem for Rosenbrock {
///     type Error = std::convert::Infallible;
///     fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), Self::Error> {
///         r.clear();
///         r.extend([10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]);
///         Ok(())
///     }
/// }
/// let found = LevenbergMarquardt::new().minimize(&mut Rosenbrock, &[-1.2, 1.0], |_| {
///     std::ops::ControlFlow::Continue(())
/// })?;
/// assert!((found.x[0] - 1.0).abs() < 1e-6 && (found.x[1] - 1.0).abs() < 1e-6);
/// assert!(matches!(found.reason, TerminationReason::Converged | TerminationReason::DampingLimit));
/// # Ok::<(), std::convert::Infallible>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LevenbergMarquardt {
    max_iterations: usize,
    tolerance: f64,
    damping: Damping,
    initial_damping: f64,
    max_damping: f64,
    min_damping: f64,
}

impl Default for LevenbergMarquardt {
    fn default() -> Self {
        Self::new()
    }
}

impl LevenbergMarquardt {
    /// The defaults of the table above.
    pub fn new() -> Self {
        Self {
            max_iterations: 100,
            tolerance: 1e-12,
            damping: Damping::Identity,
            initial_damping: 1e-3,
            max_damping: 1e10,
            min_damping: 1e-12,
        }
    }

    /// Iterations (each one Gauss-Newton model and up to a few trial steps).
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self
    }

    /// Relative cost decrease below which an accepted step ends the run.
    pub fn tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = tolerance;
        self
    }

    /// How the damping enters the step equations.
    pub fn damping(mut self, damping: Damping) -> Self {
        self.damping = damping;
        self
    }

    /// The damping of the first trial step.
    pub fn initial_damping(mut self, mu: f64) -> Self {
        self.initial_damping = mu;
        self
    }

    /// The largest damping tried before the run ends at
    /// [`TerminationReason::DampingLimit`].
    pub fn max_damping(mut self, mu: f64) -> Self {
        self.max_damping = mu;
        self
    }

    /// Minimize `problem` from `start`. After every accepted step `observe`
    /// sees the iterate and may stop the run
    /// ([`TerminationReason::EarlyStopping`]).
    ///
    /// # Errors
    /// The first error of the problem's evaluations.
    pub fn minimize<P: LeastSquaresProblem>(
        &self,
        problem: &mut P,
        start: &[f64],
        mut observe: impl FnMut(&Iterate<'_>) -> ControlFlow<()>,
    ) -> Result<Minimum, P::Error> {
        let mut run = self.run(start.to_vec(), 1);
        loop {
            match run.need() {
                Need::Evaluations => {
                    for point in run.evaluations_mut() {
                        problem.project(&mut point.x);
                        problem.residuals(&point.x, &mut point.residuals)?;
                        point.cost = problem.cost(&point.x, &point.residuals);
                    }
                    run.evaluated();
                }
                Need::Model => {
                    let model = run.model_mut();
                    problem.gauss_newton(model.x, model.residuals, model.jtj, model.jtr)?;
                    run.modelled();
                }
                Need::Observe => {
                    let stop = observe(&run.iterate()).is_break();
                    run.proceed(stop);
                }
                Need::Done => return Ok(run.finish()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tables and reports write these names: they stay what they were when
    /// a reason was added, whatever the variants are called in the code;
    /// and every reason's place in a stored file (its serde index) stays.
    #[test]
    fn reasons_keep_their_names_and_places() {
        let all = [
            (TerminationReason::EarlyStopping, "EarlyStopping"),
            (TerminationReason::MaxIterations, "MaxIterations"),
            (TerminationReason::DampingLimit, "DampingLimit"),
            (TerminationReason::Converged, "Converged"),
            (TerminationReason::MaxEpochs, "MaxEpochs"),
            (
                TerminationReason::EpochsWithoutImprovement,
                "EpochsWithoutImprovement",
            ),
            (TerminationReason::EvaluationFailed, "EvaluationFailed"),
            (TerminationReason::Deadline, "Deadline"),
            (
                TerminationReason::EpochsUntilDeadline,
                "EpochsUntilDeadline",
            ),
        ];
        for (index, (reason, name)) in all.into_iter().enumerate() {
            assert_eq!(reason.name(), name);
            let stored = postcard::to_allocvec(&reason).unwrap();
            assert_eq!(stored, vec![u8::try_from(index).unwrap()], "{name}");
        }
    }

    /// A linear problem r = A x - b: one Gauss-Newton step from anywhere
    /// lands on the least-squares solution, found independently here from
    /// the 2 x 2 normal equations by Cramer's rule.
    struct Linear;
    impl LeastSquaresProblem for Linear {
        type Error = ();
        fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), ()> {
            r.clear();
            for (a0, a1, b) in [
                (1.0, 0.0, 1.0),
                (1.0, 1.0, 2.0),
                (1.0, 2.0, 2.0),
                (1.0, 3.0, 5.0),
            ] {
                r.push(a0 * x[0] + a1 * x[1] - b);
            }
            Ok(())
        }
    }

    #[test]
    fn linear_least_squares_matches_the_closed_form() {
        // Normal equations [[4, 6], [6, 14]] x = [10, 21].
        let det = 4.0 * 14.0 - 36.0;
        let want = [
            (10.0 * 14.0 - 6.0 * 21.0) / det,
            (4.0 * 21.0 - 6.0 * 10.0) / det,
        ];
        let found = LevenbergMarquardt::new()
            .minimize(&mut Linear, &[5.0, -3.0], |_| ControlFlow::Continue(()))
            .unwrap();
        for (got, want) in found.x.iter().zip(want) {
            assert!((got - want).abs() < 1e-8, "{:?} vs {want}", found.x);
        }
    }

    #[test]
    fn the_observer_can_stop_and_the_budget_is_kept() {
        let mut seen = 0;
        let found = LevenbergMarquardt::new()
            .minimize(&mut Linear, &[5.0, -3.0], |it| {
                seen = it.iteration;
                ControlFlow::Break(())
            })
            .unwrap();
        assert_eq!(
            (found.reason, found.iterations, seen),
            (TerminationReason::EarlyStopping, 1, 1)
        );
        let found = LevenbergMarquardt::new()
            .max_iterations(1)
            .tolerance(0.0)
            .minimize(&mut Linear, &[5.0, -3.0], |_| ControlFlow::Continue(()))
            .unwrap();
        assert_eq!(
            (found.reason, found.iterations),
            (TerminationReason::MaxIterations, 1)
        );
    }

    /// A box: the minimum of (x - 3)^2 within [0, 1] is 1, reached by
    /// projected steps.
    struct Boxed;
    impl LeastSquaresProblem for Boxed {
        type Error = ();
        fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), ()> {
            r.clear();
            r.push(x[0] - 3.0);
            Ok(())
        }
        fn project(&self, x: &mut [f64]) {
            x[0] = x[0].clamp(0.0, 1.0);
        }
    }

    /// Residuals undefined below zero (an error there), a start on that
    /// face: the differences must step inward, and the minimum is found.
    struct HalfLine {
        bounds: (Vec<f64>, Vec<f64>),
    }
    impl LeastSquaresProblem for HalfLine {
        type Error = String;
        fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), String> {
            if x[0] < 0.0 {
                return Err(format!("evaluated outside the domain at {}", x[0]));
            }
            r.clear();
            r.push(x[0] * x[0] - 0.25);
            Ok(())
        }
        fn domain(&self) -> Option<(&[f64], &[f64])> {
            Some((&self.bounds.0, &self.bounds.1))
        }
        fn project(&self, x: &mut [f64]) {
            x[0] = x[0].clamp(0.0, 10.0);
        }
    }

    #[test]
    fn differences_stay_inside_the_domain() {
        let mut problem = HalfLine {
            bounds: (vec![0.0], vec![10.0]),
        };
        let found = LevenbergMarquardt::new()
            .minimize(&mut problem, &[0.0], |_| ControlFlow::Continue(()))
            .unwrap();
        assert!((found.x[0] - 0.5).abs() < 1e-6, "{found:?}");
    }

    /// Rosenbrock as least squares, counting its evaluations.
    struct Rosenbrock(usize);
    impl LeastSquaresProblem for Rosenbrock {
        type Error = ();
        fn residuals(&mut self, x: &[f64], r: &mut Vec<f64>) -> Result<(), ()> {
            self.0 += 1;
            r.clear();
            r.extend([10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]]);
            Ok(())
        }
    }

    /// Drive a run by hand, asking for `trials` dampings at once: the
    /// minimum and the number of requests for trial points.
    fn by_hand(trials: usize, start: &[f64]) -> (Minimum, usize) {
        let mut problem = Rosenbrock(0);
        let mut run = LevenbergMarquardt::new().run(start.to_vec(), trials);
        let mut requests = 0;
        loop {
            match run.need() {
                Need::Evaluations => {
                    requests += 1;
                    for point in run.evaluations_mut() {
                        problem.residuals(&point.x, &mut point.residuals).unwrap();
                        point.cost = problem.cost(&point.x, &point.residuals);
                    }
                    run.evaluated();
                }
                Need::Model => {
                    let m = run.model_mut();
                    problem
                        .gauss_newton(m.x, m.residuals, m.jtj, m.jtr)
                        .unwrap();
                    run.modelled();
                }
                Need::Observe => run.proceed(false),
                Need::Done => return (run.finish(), requests),
            }
        }
    }

    #[test]
    fn trial_dampings_asked_together_end_at_the_same_bits() {
        // From far off, many steps are refused before one is taken.
        let start = [-3.0, 8.0];
        let mut problem = Rosenbrock(0);
        let alone = LevenbergMarquardt::new()
            .minimize(&mut problem, &start, |_| ControlFlow::Continue(()))
            .unwrap();
        assert!((alone.x[0] - 1.0).abs() < 1e-6, "{alone:?}");
        let (one, one_requests) = by_hand(1, &start);
        let (three, three_requests) = by_hand(3, &start);
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        for found in [&one, &three] {
            assert_eq!(bits(&found.x), bits(&alone.x));
            assert_eq!(found.cost.to_bits(), alone.cost.to_bits());
            assert_eq!(
                (found.iterations, found.reason),
                (alone.iterations, alone.reason)
            );
        }
        // Refused steps cost no extra request when asked together.
        assert!(
            three_requests < one_requests,
            "{three_requests} vs {one_requests}"
        );
    }

    #[test]
    fn projected_steps_stay_feasible() {
        let found = LevenbergMarquardt::new()
            .damping(Damping::Diagonal { floor: 1e-12 })
            .minimize(&mut Boxed, &[0.2], |it| {
                assert!((0.0..=1.0).contains(&it.x[0]));
                ControlFlow::Continue(())
            })
            .unwrap();
        assert!((found.x[0] - 1.0).abs() < 1e-12 && (found.cost - 4.0).abs() < 1e-12);
        assert_eq!(found.reason, TerminationReason::DampingLimit);
    }
}
