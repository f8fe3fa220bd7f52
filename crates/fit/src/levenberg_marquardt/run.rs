//! The Levenberg-Marquardt iteration as a machine that asks for its
//! evaluations instead of making them: [`LevenbergMarquardt::minimize`]
//! answers one run's questions as they come; a caller holding many runs
//! (the descents of a refinement, each start and each record) answers all
//! their questions of a round together, which is how a simulator that
//! costs the same for one point as for fifty is asked once per round.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Mat, MatMut, Par};

use super::{Damping, Iterate, LevenbergMarquardt, Minimum, TerminationReason};

/// A point a run asks to have evaluated: fill in its residuals and their
/// cost (the problem's [`cost`](super::LeastSquaresProblem::cost); an
/// infinite or NaN cost rejects a trial point). A caller may move `x`
/// into its feasible set first (a problem's
/// [`project`](super::LeastSquaresProblem::project)): the run keeps the
/// point as evaluated.
#[derive(Debug, Clone, Default)]
pub struct Evaluation {
    /// Where to evaluate.
    pub x: Vec<f64>,
    /// The residuals there.
    pub residuals: Vec<f64>,
    /// Their cost.
    pub cost: f64,
}

/// What a [`LmRun`] needs next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Need {
    /// Evaluate [`LmRun::evaluations_mut`], then call [`LmRun::evaluated`].
    /// The first request is the start alone; later ones are trial steps of
    /// increasing damping, of which the first that lowers the cost is taken.
    Evaluations,
    /// The Gauss-Newton model at the current point: fill
    /// [`LmRun::model_mut`], then call [`LmRun::modelled`].
    Model,
    /// A step was accepted: show [`LmRun::iterate`] to whoever observes,
    /// then call [`LmRun::proceed`].
    Observe,
    /// The run has ended: [`LmRun::finish`].
    Done,
}

/// The Gauss-Newton model a run asks for, at its current point.
#[derive(Debug)]
pub struct ModelAt<'a> {
    /// The current point.
    pub x: &'a [f64],
    /// Its residuals.
    pub residuals: &'a [f64],
    /// `J'J` (row-major n x n; the lower triangle is read).
    pub jtj: &'a mut [f64],
    /// `J'r`.
    pub jtr: &'a mut [f64],
}

/// One Levenberg-Marquardt run, driven from outside (see [`Need`]). The
/// arithmetic is [`LevenbergMarquardt::minimize`]'s, whatever the number
/// of trial points asked for at once: a run that evaluates several trial
/// dampings together accepts the same step as one that tries them in turn,
/// and ends at the same bits.
///
/// ```
/// use twostage_fit::{LevenbergMarquardt, Need};
/// // Minimize (x - 3)^2 + (2 x)^2 / 4 by hand: residuals [x - 3, x].
/// let mut run = LevenbergMarquardt::new().run(vec![0.0], 3);
/// loop {
///     match run.need() {
///         Need::Evaluations => {
///             for e in run.evaluations_mut() {
///                 e.residuals = vec![e.x[0] - 3.0, e.x[0]];
///                 e.cost = e.residuals.iter().map(|r| r * r).sum();
///             }
///             run.evaluated();
///         }
///         Need::Model => {
///             // J = [1, 1]': J'J = 2, J'r = (x - 3) + x.
///             let m = run.model_mut();
///             m.jtj[0] = 2.0;
///             m.jtr[0] = m.residuals[0] + m.residuals[1];
///             run.modelled();
///         }
///         Need::Observe => run.proceed(false),
///         Need::Done => break,
///     }
/// }
/// let found = run.finish();
/// assert!((found.x[0] - 1.5).abs() < 1e-9);
/// ```
pub struct LmRun {
    settings: LevenbergMarquardt,
    /// Trial points evaluated together (at least 1).
    trials_at_once: usize,
    x: Vec<f64>,
    r: Vec<f64>,
    cost: f64,
    jtj: Vec<f64>,
    jtr: Vec<f64>,
    factor: Mat<f64>,
    scratch: MemBuffer,
    step: Vec<f64>,
    mu: f64,
    iterations: usize,
    reason: TerminationReason,
    /// The points asked for; their buffers are reused, and swapped with
    /// the current point's when a trial is accepted.
    pending: Vec<Evaluation>,
    /// How many of `pending` are asked for now.
    asked: usize,
    /// The damping of each asked trial.
    trial_damping: Vec<f64>,
    /// The damping to go on from when every asked trial is refused.
    next_damping: f64,
    started: bool,
    need: Need,
}

impl LevenbergMarquardt {
    /// A run from `start`, asking for up to `trials_at_once` trial
    /// dampings per request (1 is [`Self::minimize`]'s own pace; more
    /// suits an evaluation that costs the same for a few points as for
    /// one, and ends at the same point).
    pub fn run(&self, start: Vec<f64>, trials_at_once: usize) -> LmRun {
        let n = start.len();
        let scratch = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
            n,
            Par::Seq,
            Default::default(),
        ));
        LmRun {
            settings: self.clone(),
            trials_at_once: trials_at_once.max(1),
            x: Vec::new(),
            r: Vec::new(),
            cost: f64::INFINITY,
            jtj: vec![0.0; n * n],
            jtr: vec![0.0; n],
            factor: Mat::zeros(n, n),
            scratch,
            step: vec![0.0; n],
            mu: self.initial_damping,
            iterations: 0,
            reason: TerminationReason::MaxIterations,
            pending: vec![Evaluation {
                x: start,
                ..Evaluation::default()
            }],
            asked: 1,
            trial_damping: Vec::new(),
            next_damping: self.initial_damping,
            started: false,
            need: Need::Evaluations,
        }
    }
}

impl std::fmt::Debug for LmRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LmRun")
            .field("x", &self.x)
            .field("cost", &self.cost)
            .field("damping", &self.mu)
            .field("iterations", &self.iterations)
            .field("need", &self.need)
            .finish_non_exhaustive()
    }
}

impl LmRun {
    /// What the run needs next.
    pub fn need(&self) -> Need {
        self.need
    }

    /// The points to evaluate (with [`Need::Evaluations`]; empty otherwise).
    pub fn evaluations_mut(&mut self) -> &mut [Evaluation] {
        match self.need {
            Need::Evaluations => &mut self.pending[..self.asked],
            _ => &mut [],
        }
    }

    /// The points asked for have been evaluated: take the start, or the
    /// first trial (in order of damping) that lowers the cost.
    pub fn evaluated(&mut self) {
        if self.need != Need::Evaluations {
            return;
        }
        if !self.started {
            self.started = true;
            let start = &mut self.pending[0];
            std::mem::swap(&mut self.x, &mut start.x);
            std::mem::swap(&mut self.r, &mut start.residuals);
            self.cost = start.cost;
            self.next_iteration();
            return;
        }
        let accepted = self.pending[..self.asked]
            .iter()
            .position(|trial| trial.cost < self.cost);
        match accepted {
            Some(i) => {
                let trial = &mut self.pending[i];
                let relative = (self.cost - trial.cost) / self.cost.max(f64::MIN_POSITIVE);
                std::mem::swap(&mut self.x, &mut trial.x);
                std::mem::swap(&mut self.r, &mut trial.residuals);
                self.cost = trial.cost;
                self.mu = (self.trial_damping[i] / 10.0).max(self.settings.min_damping);
                if relative < self.settings.tolerance {
                    self.reason = TerminationReason::Converged;
                }
                self.need = Need::Observe;
            }
            None => {
                self.mu = self.next_damping;
                self.plan_trials();
            }
        }
    }

    /// The Gauss-Newton model to fill (with [`Need::Model`]).
    pub fn model_mut(&mut self) -> ModelAt<'_> {
        ModelAt {
            x: &self.x,
            residuals: &self.r,
            jtj: &mut self.jtj,
            jtr: &mut self.jtr,
        }
    }

    /// The model has been filled: plan the trial steps.
    pub fn modelled(&mut self) {
        if self.need == Need::Model {
            self.plan_trials();
        }
    }

    /// The accepted iterate (with [`Need::Observe`]).
    pub fn iterate(&self) -> Iterate<'_> {
        Iterate {
            iteration: self.iterations,
            x: &self.x,
            cost: self.cost,
            damping: self.mu,
        }
    }

    /// Go on after an accepted step, or stop if the observer says so
    /// ([`TerminationReason::EarlyStopping`]).
    pub fn proceed(&mut self, stop: bool) {
        if self.need != Need::Observe {
            return;
        }
        if stop {
            self.reason = TerminationReason::EarlyStopping;
            self.need = Need::Done;
        } else if self.reason == TerminationReason::Converged {
            self.need = Need::Done;
        } else {
            self.next_iteration();
        }
    }

    /// End the run where it stands, for `reason` (an evaluation of the
    /// model failed, say): the last accepted point is the answer.
    pub fn abandon(&mut self, reason: TerminationReason) {
        self.reason = reason;
        self.need = Need::Done;
    }

    /// Whether the start has been evaluated (before that there is no
    /// point to answer with).
    pub fn started(&self) -> bool {
        self.started
    }

    /// Where the run ended (or stands): the last accepted point.
    pub fn finish(self) -> Minimum {
        Minimum {
            x: self.x,
            cost: self.cost,
            iterations: self.iterations,
            reason: self.reason,
        }
    }

    fn next_iteration(&mut self) {
        if self.iterations >= self.settings.max_iterations {
            self.reason = TerminationReason::MaxIterations;
            self.need = Need::Done;
        } else {
            self.iterations += 1;
            self.need = Need::Model;
        }
    }

    /// Trial points for the dampings `mu, 10 mu, ...` (skipping those whose
    /// damped matrix is not positive definite), up to `trials_at_once`;
    /// none left below the largest damping ends the run.
    fn plan_trials(&mut self) {
        self.asked = 0;
        self.trial_damping.clear();
        let mut mu = self.mu;
        while mu <= self.settings.max_damping && self.asked < self.trials_at_once {
            if self.damped_step(mu) {
                if self.pending.len() == self.asked {
                    self.pending.push(Evaluation::default());
                }
                let trial = &mut self.pending[self.asked];
                trial.x.clear();
                trial
                    .x
                    .extend(self.x.iter().zip(&self.step).map(|(a, s)| a + s));
                self.trial_damping.push(mu);
                self.asked += 1;
            }
            mu *= 10.0;
        }
        self.next_damping = mu;
        self.need = if self.asked == 0 {
            self.reason = TerminationReason::DampingLimit;
            Need::Done
        } else {
            Need::Evaluations
        };
    }

    /// Solve `(J'J + D(mu)) step = -J'r` by Cholesky (on one thread, so
    /// the step does not depend on the thread count); false when the damped
    /// matrix is not positive definite.
    fn damped_step(&mut self, mu: f64) -> bool {
        let n = self.jtr.len();
        let (jtj, factor) = (&self.jtj, &mut self.factor);
        for i in 0..n {
            for j in 0..i {
                factor[(i, j)] = jtj[i * n + j];
            }
            let diagonal = jtj[i * n + i];
            factor[(i, i)] = match self.settings.damping {
                Damping::Identity => diagonal + mu,
                Damping::Diagonal { floor } => diagonal + mu * (diagonal + floor),
            };
        }
        let factored = llt::factor::cholesky_in_place(
            factor.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
            Default::default(),
        );
        // faer refuses every pivot that is not `> 0`, NaN included.
        if factored.is_err() {
            return false;
        }
        for (s, g) in self.step.iter_mut().zip(&self.jtr) {
            *s = -g;
        }
        llt::solve::solve_in_place(
            self.factor.as_ref(),
            MatMut::from_column_major_slice_mut(&mut self.step, n, 1),
            Par::Seq,
            MemStack::new(&mut MemBuffer::new(
                llt::solve::solve_in_place_scratch::<f64>(n, 1, Par::Seq),
            )),
        );
        true
    }
}
