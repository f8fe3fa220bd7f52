//! A fixed-step classic fourth-order Runge-Kutta integrator.

/// A system of ordinary differential equations `x' = f(t, x)`.
///
/// The right-hand side writes into a caller-provided buffer, so that
/// integrating allocates nothing.
pub trait OdeSystem {
    /// The state dimension.
    fn dim(&self) -> usize;
    /// Write `f(t, x)` into `dx` (both of length [`OdeSystem::dim`]).
    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]);
}

/// Classic RK4 with its scratch space, reusable across steps and systems
/// of the same dimension.
///
/// ```
/// use twostage_models::{OdeSystem, Rk4};
/// // x' = -x, x(0) = 1: x(1) = e^-1.
/// struct Decay;
/// impl OdeSystem for Decay {
///     fn dim(&self) -> usize { 1 }
///     fn rhs(&self, _t: f64, x: &[f64], dx: &mut [f64]) { dx[0] = -x[0]; }
/// }
/// let mut x = [1.0];
/// Rk4::new(1).integrate(&Decay, 0.0, 0.01, 100, &mut x);
/// assert!((x[0] - (-1.0f64).exp()).abs() < 1e-9);
/// ```
#[derive(Debug, Clone)]
pub struct Rk4 {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    stage: Vec<f64>,
}

impl Rk4 {
    /// Scratch space for systems of dimension `dim`.
    pub fn new(dim: usize) -> Self {
        Self {
            k1: vec![0.0; dim],
            k2: vec![0.0; dim],
            k3: vec![0.0; dim],
            k4: vec![0.0; dim],
            stage: vec![0.0; dim],
        }
    }

    /// Advance `x` from `t` to `t + h` by one RK4 step.
    ///
    /// Panics if `x` or the system's dimension differ from this
    /// integrator's: that is a programming error, not a data error.
    pub fn step<S: OdeSystem + ?Sized>(&mut self, system: &S, t: f64, h: f64, x: &mut [f64]) {
        let n = self.stage.len();
        assert!(
            x.len() == n && system.dim() == n,
            "Rk4 built for dimension {n}, used with a state of {} and a system of {}",
            x.len(),
            system.dim()
        );
        let half = 0.5 * h;
        system.rhs(t, x, &mut self.k1);
        offset(&mut self.stage, x, half, &self.k1);
        system.rhs(t + half, &self.stage, &mut self.k2);
        offset(&mut self.stage, x, half, &self.k2);
        system.rhs(t + half, &self.stage, &mut self.k3);
        offset(&mut self.stage, x, h, &self.k3);
        system.rhs(t + h, &self.stage, &mut self.k4);
        let sixth = h / 6.0;
        let slopes = self
            .k1
            .iter()
            .zip(&self.k2)
            .zip(self.k3.iter().zip(&self.k4));
        for (xi, ((k1, k2), (k3, k4))) in x.iter_mut().zip(slopes) {
            *xi += sixth * (k1 + 2.0 * (k2 + k3) + k4);
        }
    }

    /// Take `steps` steps of size `h` from `t0`. Step `j` starts at
    /// `t0 + j h` (computed from `j`, so time does not drift by rounding).
    pub fn integrate<S: OdeSystem + ?Sized>(
        &mut self,
        system: &S,
        t0: f64,
        h: f64,
        steps: usize,
        x: &mut [f64],
    ) {
        for j in 0..steps {
            self.step(system, t0 + j as f64 * h, h, x);
        }
    }
}

/// `stage = x + a k`, the state at which the next slope is evaluated.
fn offset(stage: &mut [f64], x: &[f64], a: f64, k: &[f64]) {
    for ((s, xi), ki) in stage.iter_mut().zip(x).zip(k) {
        *s = xi + a * ki;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damped, forced oscillator with a closed-form solution:
    /// x'' + 2 x' + 5 x = 0 from x(0) = 1, x'(0) = 0 gives
    /// x(t) = e^-t (cos 2t + sin(2t) / 2), plus a time-dependent term so
    /// that the stage times matter: add sin(t) to the force and its
    /// particular solution (A sin t + B cos t with A = 0.2, B = -0.1).
    struct Oscillator;

    impl OdeSystem for Oscillator {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -2.0 * x[1] - 5.0 * x[0] + t.sin();
        }
    }

    fn exact(t: f64) -> f64 {
        // Particular solution xp = 0.2 sin t - 0.1 cos t; homogeneous part
        // fitted to x(0) = 1, x'(0) = 0: c1 = 1.1, c2 = (0 - 0.2 + 1.1) / 2 = 0.45.
        let (a, b) = (0.2, -0.1);
        let c1 = 1.0 - b;
        let c2 = (-a + c1) / 2.0;
        (-t).exp() * (c1 * (2.0 * t).cos() + c2 * (2.0 * t).sin()) + a * t.sin() + b * t.cos()
    }

    fn error_at_3(h: f64) -> f64 {
        let steps = (3.0 / h).round() as usize;
        let mut x = [1.0, 0.0];
        Rk4::new(2).integrate(&Oscillator, 0.0, h, steps, &mut x);
        (x[0] - exact(3.0)).abs()
    }

    #[test]
    fn closed_form_is_a_solution() {
        // Check the reference itself by finite differences, so that the
        // order test below compares against a true solution.
        let h = 1e-4;
        for t in [0.3, 1.0, 2.5] {
            let d1 = (exact(t + h) - exact(t - h)) / (2.0 * h);
            let d2 = (exact(t + h) - 2.0 * exact(t) + exact(t - h)) / (h * h);
            assert!((d2 + 2.0 * d1 + 5.0 * exact(t) - t.sin()).abs() < 1e-5);
        }
        assert!((exact(0.0) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn halving_the_step_divides_the_error_by_sixteen() {
        for h in [0.1, 0.05, 0.025] {
            let ratio = error_at_3(h) / error_at_3(h / 2.0);
            assert!((14.0..18.5).contains(&ratio), "h = {h}: ratio {ratio}");
        }
    }
}
