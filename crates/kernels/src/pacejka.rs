//! The Pacejka car's equations (spec/pacejka-car.md), written once for any
//! number that [`Real`] describes: plain `f64` for the simulator, and
//! [`Dual2`], which carries its derivatives with respect to the two tire
//! parameters, for the stage 1 that linearizes the car
//! ([`crate::linearized`]). Host and control unit run this code, so both
//! compute the same car.

use core::ops::{Add, Div, Mul, Neg, Sub};

/// The arithmetic the car's equations need. For `f64` the operations are
/// the plain ones (with `std`, the platform's `sin` and `atan`, as the
/// simulator has always used; without, libm's).
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// A number that does not depend on the parameters.
    fn constant(x: f64) -> Self;
    /// Its value.
    fn value(self) -> f64;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Arc tangent.
    fn atan(self) -> Self;
    /// Sine and cosine, as `(self.sin(), self.cos())` give them.
    fn sin_cos(self) -> (Self, Self) {
        (self.sin(), self.cos())
    }
}

/// The sine and cosine of `x` in one call.
#[inline]
fn sin_cos(x: f64) -> (f64, f64) {
    #[cfg(feature = "std")]
    {
        f64::sin_cos(x)
    }
    #[cfg(not(feature = "std"))]
    {
        libm::sincos(x)
    }
}

impl Real for f64 {
    #[inline]
    fn constant(x: f64) -> Self {
        x
    }
    #[inline]
    fn value(self) -> f64 {
        self
    }
    #[inline]
    fn sin(self) -> Self {
        #[cfg(feature = "std")]
        {
            f64::sin(self)
        }
        #[cfg(not(feature = "std"))]
        {
            libm::sin(self)
        }
    }
    #[inline]
    fn cos(self) -> Self {
        #[cfg(feature = "std")]
        {
            f64::cos(self)
        }
        #[cfg(not(feature = "std"))]
        {
            libm::cos(self)
        }
    }
    #[inline]
    fn atan(self) -> Self {
        #[cfg(feature = "std")]
        {
            f64::atan(self)
        }
        #[cfg(not(feature = "std"))]
        {
            libm::atan(self)
        }
    }
}

/// A number with its derivatives with respect to two parameters (forward
/// mode): every operation applies the chain rule, so a simulation computed
/// with it gives the output's exact derivatives along with the output.
///
/// ```
/// use twostage_kernels::pacejka::{Dual2, Real};
/// // f(a, b) = sin(a b) at (2, 3): df/da = 3 cos 6, df/db = 2 cos 6.
/// let (a, b) = (Dual2::variable(2.0, 0), Dual2::variable(3.0, 1));
/// let f = (a * b).sin();
/// assert_eq!(f.value, 6f64.sin());
/// assert!((f.grad[0] - 3.0 * 6f64.cos()).abs() < 1e-15);
/// assert!((f.grad[1] - 2.0 * 6f64.cos()).abs() < 1e-15);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dual2 {
    /// The number.
    pub value: f64,
    /// Its derivative with respect to the first and the second parameter.
    pub grad: [f64; 2],
}

impl Dual2 {
    /// Parameter `which` (0 or 1) at `value`: its own derivative is 1.
    pub fn variable(value: f64, which: usize) -> Self {
        let mut grad = [0.0; 2];
        if let Some(g) = grad.get_mut(which) {
            *g = 1.0;
        }
        Self { value, grad }
    }

    /// The number whose derivatives are `d` times this one's.
    #[inline]
    fn chain(self, value: f64, d: f64) -> Self {
        Self {
            value,
            grad: [d * self.grad[0], d * self.grad[1]],
        }
    }
}

impl Add for Dual2 {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self {
            value: self.value + o.value,
            grad: [self.grad[0] + o.grad[0], self.grad[1] + o.grad[1]],
        }
    }
}

impl Sub for Dual2 {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self {
            value: self.value - o.value,
            grad: [self.grad[0] - o.grad[0], self.grad[1] - o.grad[1]],
        }
    }
}

impl Mul for Dual2 {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        Self {
            value: self.value * o.value,
            grad: [
                self.grad[0] * o.value + self.value * o.grad[0],
                self.grad[1] * o.value + self.value * o.grad[1],
            ],
        }
    }
}

impl Div for Dual2 {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        let value = self.value / o.value;
        Self {
            value,
            grad: [
                (self.grad[0] - value * o.grad[0]) / o.value,
                (self.grad[1] - value * o.grad[1]) / o.value,
            ],
        }
    }
}

impl Neg for Dual2 {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self {
            value: -self.value,
            grad: [-self.grad[0], -self.grad[1]],
        }
    }
}

impl Real for Dual2 {
    #[inline]
    fn constant(x: f64) -> Self {
        Self {
            value: x,
            grad: [0.0; 2],
        }
    }
    #[inline]
    fn value(self) -> f64 {
        self.value
    }
    #[inline]
    fn sin(self) -> Self {
        let (s, c) = sin_cos(self.value);
        self.chain(s, c)
    }
    #[inline]
    fn cos(self) -> Self {
        let (s, c) = sin_cos(self.value);
        self.chain(c, -s)
    }
    #[inline]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = sin_cos(self.value);
        (self.chain(s, c), self.chain(c, -s))
    }
    #[inline]
    fn atan(self) -> Self {
        let v = self.value;
        self.chain(Real::atan(v), 1.0 / (1.0 + v * v))
    }
}

/// Vehicle constants (spec/pacejka-car.md, "Constants").
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Vehicle {
    /// Mass m, kg.
    pub mass: f64,
    /// Yaw inertia J, kg m^2.
    pub yaw_inertia: f64,
    /// Centre of mass to front axle lf, m.
    pub lf: f64,
    /// Centre of mass to rear axle lr, m.
    pub lr: f64,
    /// Track width l, m.
    pub track: f64,
    /// Centre-of-mass height h, m.
    pub cg_height: f64,
    /// Gravity g, m/s^2.
    pub gravity: f64,
    /// Speed V, m/s.
    pub speed: f64,
    /// Roll inertia Jr, kg m^2.
    pub roll_inertia: f64,
    /// Roll damping Cr, N m s/rad.
    pub roll_damping: f64,
    /// Roll stiffness Kr, N m/rad.
    pub roll_stiffness: f64,
}

impl Vehicle {
    /// The mid-size car of the spec.
    pub const PAPER: Self = Self {
        mass: 1500.0,
        yaw_inertia: 2500.0,
        lf: 1.1,
        lr: 1.6,
        track: 1.5,
        cg_height: 0.5,
        gravity: 9.81,
        speed: 10.0,
        roll_inertia: 700.0,
        roll_damping: 5000.0,
        roll_stiffness: 80000.0,
    };

    /// Static load of each axle, `(N_f, N_r)`.
    pub fn axle_loads(&self) -> (f64, f64) {
        let weight = self.mass * self.gravity;
        let wheelbase = self.lf + self.lr;
        (weight * self.lr / wheelbase, weight * self.lf / wheelbase)
    }
}

/// Tire constants of Pacejka's magic formula; pK1 and pK2 are the unknown
/// parameters and are passed separately.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[allow(missing_docs)] // the fields are the formula's own symbols
pub struct Tire {
    /// Nominal load Fz0, N.
    pub fz0: f64,
    /// Camber angle gamma, rad.
    pub camber: f64,
    pub p_c1: f64,
    pub p_d1: f64,
    pub p_d2: f64,
    pub p_d3: f64,
    pub p_e1: f64,
    pub p_e2: f64,
    pub p_e3: f64,
    pub p_e4: f64,
    pub p_h1: f64,
    pub p_h2: f64,
    pub p_h3: f64,
    pub p_v1: f64,
    pub p_v2: f64,
    pub p_v3: f64,
    pub p_v4: f64,
    pub p_k3: f64,
}

impl Tire {
    /// The tire of the spec (all four alike).
    pub const PAPER: Self = Self {
        fz0: 4000.0,
        camber: 0.0,
        p_c1: 1.3,
        p_d1: 1.0,
        p_d2: -0.1,
        p_d3: 0.0,
        p_e1: -0.5,
        p_e2: -0.2,
        p_e3: 0.0,
        p_e4: 0.0,
        p_h1: 0.0,
        p_h2: 0.0,
        p_h3: 0.0,
        p_v1: 0.0,
        p_v2: 0.0,
        p_v3: 0.0,
        p_v4: 0.0,
        p_k3: 0.0,
    };

    /// Lateral force of one wheel with load `q` and slip angle `alpha`,
    /// Pacejka's magic formula as printed in the paper (Section 6.1).
    ///
    /// ```
    /// use twostage_kernels::pacejka::Tire;
    /// let t = Tire::PAPER;
    /// // Small slip: F = K alpha with K = pK1 Fz0 sin(2 atan(Q / (pK2 Fz0))).
    /// let (pk1, pk2, q, alpha) = (-35.0, -1.1, 4000.0, 1e-7);
    /// let k = pk1 * t.fz0 * (2.0 * (q / (pk2 * t.fz0)).atan()).sin();
    /// assert!((t.lateral_force(q, alpha, pk1, pk2) / (k * alpha) - 1.0).abs() < 1e-6);
    /// ```
    pub fn lateral_force<R: Real>(&self, q: R, alpha: R, p_k1: R, p_k2: R) -> R {
        let c_ = R::constant;
        let gamma = self.camber;
        let fz0 = c_(self.fz0);
        let fz = (q - fz0) / fz0;
        let s_h = c_(self.p_h1) + c_(self.p_h2) * fz + c_(self.p_h3 * gamma);
        let s_v = q
            * ((c_(self.p_v1) + c_(self.p_v2) * fz)
                + (c_(self.p_v3) + c_(self.p_v4) * fz) * c_(gamma));
        let a = alpha + s_h;
        let c = self.p_c1;
        let mu = (c_(self.p_d1) + c_(self.p_d2) * fz) * c_(1.0 - self.p_d3 * gamma * gamma);
        let d = mu * q;
        let e = (c_(self.p_e1) + c_(self.p_e2) * fz)
            * c_(1.0 - (self.p_e3 + self.p_e4 * gamma) * sign(a.value()));
        // sin(2 atan(x)) = 2x / (1 + x^2): the same value without two
        // transcendental calls, in the innermost loop of every car simulation.
        let x = q / (p_k2 * fz0);
        let k = p_k1 * fz0 * (c_(2.0) * x / (c_(1.0) + x * x)) * c_(1.0 - self.p_k3 * gamma.abs());
        let b = k / (c_(c) * d);
        let ba = b * a;
        d * (c_(c) * (ba - e * (ba - ba.atan())).atan()).sin() + s_v
    }
}

/// The paper's sign function: `sign(0) = 0`.
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The car's constants: what its equations need besides the tire
/// parameters, the steer and the state.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Car {
    /// The vehicle.
    pub vehicle: Vehicle,
    /// The tire (all four alike).
    pub tire: Tire,
}

impl Car {
    /// The spec's car.
    pub const PAPER: Self = Self {
        vehicle: Vehicle::PAPER,
        tire: Tire::PAPER,
    };

    /// How many numbers [`Self::to_words`] writes: the vehicle's 11
    /// constants, then the tire's 18, in their declaration order.
    pub const WORDS: usize = 29;

    /// The constants as numbers, the vehicle's then the tire's, in their
    /// declaration order: how the runtime's blob stores the car.
    ///
    /// ```
    /// use twostage_kernels::pacejka::Car;
    /// let words = Car::PAPER.to_words();
    /// assert_eq!((words[0], words[11]), (1500.0, 4000.0)); // the mass, Fz0
    /// assert_eq!(Car::from_words(&words), Car::PAPER);
    /// ```
    pub fn to_words(&self) -> [f64; Self::WORDS] {
        let v = &self.vehicle;
        let t = &self.tire;
        [
            v.mass,
            v.yaw_inertia,
            v.lf,
            v.lr,
            v.track,
            v.cg_height,
            v.gravity,
            v.speed,
            v.roll_inertia,
            v.roll_damping,
            v.roll_stiffness,
            t.fz0,
            t.camber,
            t.p_c1,
            t.p_d1,
            t.p_d2,
            t.p_d3,
            t.p_e1,
            t.p_e2,
            t.p_e3,
            t.p_e4,
            t.p_h1,
            t.p_h2,
            t.p_h3,
            t.p_v1,
            t.p_v2,
            t.p_v3,
            t.p_v4,
            t.p_k3,
        ]
    }

    /// The car [`Self::to_words`] wrote.
    pub fn from_words(w: &[f64; Self::WORDS]) -> Self {
        Self {
            vehicle: Vehicle {
                mass: w[0],
                yaw_inertia: w[1],
                lf: w[2],
                lr: w[3],
                track: w[4],
                cg_height: w[5],
                gravity: w[6],
                speed: w[7],
                roll_inertia: w[8],
                roll_damping: w[9],
                roll_stiffness: w[10],
            },
            tire: Tire {
                fz0: w[11],
                camber: w[12],
                p_c1: w[13],
                p_d1: w[14],
                p_d2: w[15],
                p_d3: w[16],
                p_e1: w[17],
                p_e2: w[18],
                p_e3: w[19],
                p_e4: w[20],
                p_h1: w[21],
                p_h2: w[22],
                p_h3: w[23],
                p_v1: w[24],
                p_v2: w[25],
                p_v3: w[26],
                p_v4: w[27],
                p_k3: w[28],
            },
        }
    }

    /// Total lateral force and yaw moment for tire parameters
    /// `(pK1, pK2)`, steer `delta` and state `(beta, r, phi, p)`.
    pub fn force_and_moment<R: Real>(&self, theta: [R; 2], delta: R, x: &[R; 4]) -> (R, R) {
        self.force_and_moment_rolled(theta, delta, x, x[2].sin())
    }

    /// [`Self::force_and_moment`] with the roll angle's sine given.
    fn force_and_moment_rolled<R: Real>(
        &self,
        theta: [R; 2],
        delta: R,
        x: &[R; 4],
        sin_phi: R,
    ) -> (R, R) {
        let c_ = R::constant;
        let v = &self.vehicle;
        let (beta, r) = (x[0], x[1]);
        let alpha_f = delta - beta - c_(v.lf) * r / c_(v.speed);
        let alpha_r = -beta + c_(v.lr) * r / c_(v.speed);
        let shift = c_(v.cg_height / v.track) * sin_phi;
        let (left, right) = (c_(0.5) - shift, c_(0.5) + shift);
        let (n_f, n_r) = v.axle_loads();
        let force = |q: R, alpha: R| self.tire.lateral_force(q, alpha, theta[0], theta[1]);
        let front = force(c_(n_f) * left, alpha_f) + force(c_(n_f) * right, alpha_f);
        let rear = force(c_(n_r) * left, alpha_r) + force(c_(n_r) * right, alpha_r);
        (front + rear, c_(v.lf) * front - c_(v.lr) * rear)
    }

    /// Lateral acceleration a_y (the output) for steer `delta` and state `x`.
    pub fn lateral_acceleration<R: Real>(&self, theta: [R; 2], delta: R, x: &[R; 4]) -> R {
        self.force_and_moment(theta, delta, x).0 / R::constant(self.vehicle.mass)
    }

    /// The state's time derivative for steer `delta` and state `x`.
    pub fn derivatives<R: Real>(&self, theta: [R; 2], delta: R, x: &[R; 4]) -> [R; 4] {
        let c_ = R::constant;
        let v = &self.vehicle;
        let (r, phi, p) = (x[1], x[2], x[3]);
        let (sin_phi, cos_phi) = phi.sin_cos();
        let (force, moment) = self.force_and_moment_rolled(theta, delta, x, sin_phi);
        let a_y = force / c_(v.mass);
        let hm = v.cg_height * v.mass;
        [
            // m V (beta' + r) = sum F
            a_y / c_(v.speed) - r,
            moment / c_(v.yaw_inertia),
            p,
            (c_(hm * v.gravity) * sin_phi + a_y * c_(hm) * cos_phi
                - c_(v.roll_damping) * p
                - c_(v.roll_stiffness) * phi)
                / c_(v.roll_inertia),
        ]
    }

    /// One classic fourth-order Runge-Kutta step of `h` seconds from the
    /// state `x`, the steer `steer(tau)` at the step's fraction `tau` (0 at
    /// its start, 1 at its end).
    pub fn rk4_step<R: Real>(
        &self,
        theta: [R; 2],
        h: f64,
        steer: impl Fn(f64) -> f64,
        x: &mut [R; 4],
    ) {
        let c_ = R::constant;
        let half = 0.5 * h;
        let offset = |a: f64, k: &[R; 4]| -> [R; 4] {
            [
                x[0] + c_(a) * k[0],
                x[1] + c_(a) * k[1],
                x[2] + c_(a) * k[2],
                x[3] + c_(a) * k[3],
            ]
        };
        let mid = c_(steer(0.5));
        let k1 = self.derivatives(theta, c_(steer(0.0)), x);
        let k2 = self.derivatives(theta, mid, &offset(half, &k1));
        let k3 = self.derivatives(theta, mid, &offset(half, &k2));
        let k4 = self.derivatives(theta, c_(steer(1.0)), &offset(h, &k3));
        let sixth = c_(h / 6.0);
        for i in 0..4 {
            x[i] = x[i] + sixth * (k1[i] + c_(2.0) * (k2[i] + k3[i]) + k4[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dual numbers' derivatives of the force against central
    /// differences of the plain one, on both sides of saturation.
    #[test]
    fn the_forces_derivatives_are_the_finite_differences() {
        let t = Tire::PAPER;
        for &(alpha, q) in &[(0.01, 3900.0), (0.08, 4400.0), (-0.2, 3000.0)] {
            let (k1, k2) = (-35.0, -1.1);
            let dual = t.lateral_force(
                Dual2::constant(q),
                Dual2::constant(alpha),
                Dual2::variable(k1, 0),
                Dual2::variable(k2, 1),
            );
            assert_eq!(
                dual.value.to_bits(),
                t.lateral_force(q, alpha, k1, k2).to_bits()
            );
            let h = [1e-5, 1e-7];
            let d0 = (t.lateral_force(q, alpha, k1 + h[0], k2)
                - t.lateral_force(q, alpha, k1 - h[0], k2))
                / (2.0 * h[0]);
            let d1 = (t.lateral_force(q, alpha, k1, k2 + h[1])
                - t.lateral_force(q, alpha, k1, k2 - h[1]))
                / (2.0 * h[1]);
            assert!(
                (dual.grad[0] - d0).abs() < 1e-6 * d0.abs().max(1.0),
                "{dual:?} {d0}"
            );
            assert!(
                (dual.grad[1] - d1).abs() < 1e-5 * d1.abs().max(1.0),
                "{dual:?} {d1}"
            );
        }
    }

    /// A Runge-Kutta step of a state that carries derivatives gives the
    /// derivative of the plain step (the simulation's own sensitivity).
    #[test]
    fn a_step_carries_the_states_sensitivity() {
        let car = Car::PAPER;
        let steer = |tau: f64| 0.05 + 0.02 * tau;
        let start = [0.01, 0.05, 0.002, -0.01];
        let plain = |k1: f64| {
            let mut x = start;
            for _ in 0..20 {
                car.rk4_step([k1, -1.1], 0.01, steer, &mut x);
            }
            x
        };
        let mut x = start.map(Dual2::constant);
        for _ in 0..20 {
            car.rk4_step(
                [Dual2::variable(-35.0, 0), Dual2::variable(-1.1, 1)],
                0.01,
                steer,
                &mut x,
            );
        }
        let h = 1e-5;
        let (up, down) = (plain(-35.0 + h), plain(-35.0 - h));
        for i in 0..4 {
            assert_eq!(x[i].value.to_bits(), plain(-35.0)[i].to_bits());
            let d = (up[i] - down[i]) / (2.0 * h);
            assert!(
                (x[i].grad[0] - d).abs() < 1e-7 * d.abs().max(1e-3),
                "{i}: {:?} {d}",
                x[i]
            );
        }
    }
}
