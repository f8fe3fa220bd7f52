//! A stage 1 that regresses each record on its model's own output
//! sensitivities at the prior's centre (`linearized`,
//! [`twostage_kernels::linearized`]): least-squares coefficients, as the
//! paper's stage 1 is, of regressors that mean the same whatever input
//! drove the record. For models whose equations the kernels hold (the
//! built-in car); the model hands them over when the compressor is shaped
//! for it ([`Linearized::for_car`]).

use std::fmt;

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
use twostage_kernels::linearized::{
    CarLinearization, CarStream, LINEARIZED_FEATURES, LinearizedSums, WindowBlocks,
};

use crate::Compressor;
use crate::InvalidSetting;
use crate::error::{CompressError, Result};
use crate::signals::check_record;
use crate::workspace::Workspace;

/// Runge-Kutta steps per sample when the specification names none.
pub const DEFAULT_SUBSTEPS: u32 = 2;

pub use twostage_kernels::linearized::MAX_SUBSTEPS;

/// The linearized stage 1: `linearized` or `linearized:S` (S Runge-Kutta
/// steps per sample), then the car it linearizes once shaped for a model.
///
/// ```
/// use twostage_compress::{Compressor, CompressorConfig, Linearized};
/// use twostage_kernels::pacejka::Car;
/// let spec: CompressorConfig = "linearized".parse()?;
/// assert_eq!(spec.to_string(), "the model linearized at the prior's centre (2 steps a sample)");
/// let shaped = Linearized::new(1)?.for_car(Car::PAPER, [-42.83, -1.22], [-27.32, -0.98], 0.01, 0.02)?;
/// // A record of the car at rest says nothing: the features are the
/// // anchor, no step, and the prior's own spread.
/// let (u, y) = (ndarray::Array2::zeros((500, 1)), ndarray::Array2::zeros((500, 1)));
/// let f = shaped.compress(u.view(), y.view())?;
/// assert!((f[0] - (-35.075)).abs() < 1e-12 && f[2] == 0.0);
/// assert!((f[4] - 0.5f64.ln()).abs() < 1e-12);
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "LinearizedFields")]
pub struct Linearized {
    substeps: u32,
    car: Option<CarLinearization>,
}

/// What a file holds, checked as [`Linearized::new`] and
/// [`Linearized::for_car`] check it: a damaged file cannot ask for
/// billions of steps a sample or a box of no width.
#[derive(Deserialize)]
struct LinearizedFields {
    substeps: u32,
    car: Option<CarLinearization>,
}

impl TryFrom<LinearizedFields> for Linearized {
    type Error = CompressError;
    fn try_from(f: LinearizedFields) -> Result<Self> {
        let unshaped = Self::new(f.substeps)?;
        let Some(car) = f.car else {
            return Ok(unshaped);
        };
        let shaped = unshaped.for_car(
            car.car,
            car.lower,
            car.upper,
            car.noise_variance,
            car.sample_time,
        )?;
        // The anchor and the steps are derived: a file that says otherwise
        // was not written by this code.
        if shaped.car != Some(car) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "linearized",
                value: format!("anchor {:?}, {} steps", car.anchor, car.substeps),
                reason: "the box's centre and the configuration's steps a sample".into(),
            }));
        }
        Ok(shaped)
    }
}

impl Linearized {
    /// Not yet shaped for a model, `substeps` Runge-Kutta steps per sample.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for 0 steps or more than
    /// [`MAX_SUBSTEPS`].
    pub fn new(substeps: u32) -> Result<Self> {
        if !(1..=MAX_SUBSTEPS).contains(&substeps) {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "linearized",
                value: format!("linearized:{substeps}"),
                reason: format!("1 to {MAX_SUBSTEPS} Runge-Kutta steps a sample"),
            }));
        }
        Ok(Self {
            substeps,
            car: None,
        })
    }

    /// Runge-Kutta steps per sample.
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// The car it linearizes, once shaped for it.
    pub fn car(&self) -> Option<&CarLinearization> {
        self.car.as_ref()
    }

    /// Shaped for the car `car` whose two parameters lie in the box
    /// `[lower, upper]` (linearized at its centre), with output noise of
    /// variance `noise_variance`, sampled every `sample_time` s.
    ///
    /// # Errors
    /// [`CompressError::InvalidSetting`] for an empty or unbounded box, a
    /// noise variance or sample time that is not finite and positive.
    pub fn for_car(
        self,
        car: twostage_kernels::pacejka::Car,
        lower: [f64; 2],
        upper: [f64; 2],
        noise_variance: f64,
        sample_time: f64,
    ) -> Result<Self> {
        let refuse = |what: &str, value: String| {
            CompressError::InvalidSetting(InvalidSetting {
                name: "linearized",
                value,
                reason: format!("{what} must be finite and positive"),
            })
        };
        for j in 0..2 {
            let width = upper[j] - lower[j];
            if !(width.is_finite() && width > 0.0) {
                return Err(refuse(
                    "the prior box's width",
                    format!("[{}, {}]", lower[j], upper[j]),
                ));
            }
        }
        if !(noise_variance.is_finite() && noise_variance > 0.0) {
            return Err(refuse("the noise variance", noise_variance.to_string()));
        }
        if !(sample_time.is_finite() && sample_time > 0.0) {
            return Err(refuse("the sample time", sample_time.to_string()));
        }
        let anchor = [0.5 * (lower[0] + upper[0]), 0.5 * (lower[1] + upper[1])];
        Ok(Self {
            substeps: self.substeps,
            car: Some(CarLinearization {
                car,
                anchor,
                lower,
                upper,
                noise_variance,
                sample_time,
                substeps: self.substeps,
            }),
        })
    }

    /// The specification that makes it: `linearized` or `linearized:S`.
    pub fn spec(&self) -> String {
        if self.substeps == DEFAULT_SUBSTEPS {
            "linearized".into()
        } else {
            format!("linearized:{}", self.substeps)
        }
    }
}

impl Linearized {
    /// The features of what a runtime's sliding window of `window`
    /// samples holds at the record's end: the car runs from the record's
    /// first sample (where the plant was when the window began, not at
    /// rest), and the sums cover the window's blocks
    /// ([`twostage_kernels::linearized::WindowBlocks`]). `window` 0 is the
    /// whole record, as [`Compressor::compress_into`].
    ///
    /// ```
    /// use twostage_compress::{Compressor, Linearized};
    /// use twostage_kernels::pacejka::Car;
    /// let shaped = Linearized::new(1)?.for_car(Car::PAPER, [-42.83, -1.22], [-27.32, -0.98], 0.01, 0.02)?;
    /// let u = ndarray::Array2::from_shape_fn((400, 1), |(k, _)| 0.1 * (k as f64 * 0.05).sin());
    /// let y = ndarray::Array2::from_shape_fn((400, 1), |(k, _)| 2.0 * (k as f64 * 0.05).sin());
    /// let (mut whole, mut window) = ([0.0; 8], [0.0; 8]);
    /// shaped.compress_window(u.view(), y.view(), 0, &mut whole)?;
    /// shaped.compress_window(u.view(), y.view(), 100, &mut window)?;
    /// // A window of a quarter of the record says less of the parameters.
    /// assert!(window[4] > whole[4]);
    /// # Ok::<(), twostage_compress::CompressError>(())
    /// ```
    ///
    /// # Errors
    /// As [`Compressor::compress_into`].
    pub fn compress_window(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        window: usize,
        alpha: &mut [f64],
    ) -> Result<()> {
        let first = if window == 0 {
            0
        } else {
            WindowBlocks::of(window).first_sample(inputs.nrows())
        };
        self.features_from(inputs, outputs, first, alpha)
    }

    /// The features of the sums from sample `first` to the record's end,
    /// the car run from its first sample.
    fn features_from(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        first: usize,
        alpha: &mut [f64],
    ) -> Result<()> {
        let Some(car) = &self.car else {
            return Err(CompressError::InvalidSetting(InvalidSetting {
                name: "compressor",
                value: self.spec(),
                reason: "the linearized stage 1 needs a model whose equations twostage holds \
                         (the built-in car, or a model file of it); for other models use arx, \
                         narx or pca"
                    .into(),
            }));
        };
        check_record(
            inputs,
            outputs,
            1,
            1,
            alpha.len(),
            LINEARIZED_FEATURES,
            2,
            self,
        )?;
        let (u, y) = (inputs.column(0), outputs.column(0));
        let mut stream = CarStream::new();
        let mut sums = LinearizedSums::default();
        for (t, (u, y)) in u.iter().zip(y.iter()).enumerate() {
            let (s, r) = stream.push(car, *u, *y);
            if t >= first {
                sums.add(s, r);
            }
        }
        car.features(&sums, alpha)
            .ok_or_else(|| CompressError::RankDeficient {
                structure: self.to_string(),
                cause: "the model left its range on this record's input (its sensitivities \
                        are not finite): the record is outside what the car can drive"
                    .into(),
            })
    }
}

impl fmt::Display for Linearized {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the model linearized at the prior's centre ({} step{} a sample)",
            self.substeps,
            if self.substeps == 1 { "" } else { "s" }
        )
    }
}

impl Compressor for Linearized {
    fn n_features(&self) -> usize {
        LINEARIZED_FEATURES
    }

    fn compress_into(
        &self,
        inputs: ArrayView2<'_, f64>,
        outputs: ArrayView2<'_, f64>,
        _work: &mut Workspace,
        alpha: &mut [f64],
    ) -> Result<()> {
        self.features_from(inputs, outputs, 0, alpha)
    }

    fn feature_names(&self) -> Vec<String> {
        let names = ["pK1", "pK2"];
        let mut out: Vec<String> = names
            .iter()
            .map(|n| format!("{n} after the step"))
            .collect();
        out.extend(names.iter().map(|n| format!("{n} step / width")));
        out.extend(names.iter().map(|n| format!("log {n} sd / width")));
        out.push("correlation".into());
        out.push("log residual mean square".into());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use twostage_kernels::pacejka::Car;

    /// The features' step is the least-squares step computed another way:
    /// regressors from central differences of the plain simulation (not the
    /// dual numbers), solved by the 2 x 2 normal equations by hand.
    #[test]
    fn the_step_is_least_squares_on_finite_difference_regressors() {
        let (lower, upper) = ([-42.83, -1.22], [-27.32, -0.98]);
        let lin = Linearized::new(2)
            .unwrap()
            .for_car(Car::PAPER, lower, upper, 0.01, 0.02)
            .unwrap();
        let n = 300;
        let u: Vec<f64> = (0..n).map(|k| 0.08 * (k as f64 * 0.07).sin()).collect();
        // The plain car at theta, the input linear between samples.
        let simulate = |theta: [f64; 2]| -> Vec<f64> {
            let mut x = [0.0f64; 4];
            let mut y = Vec::with_capacity(n);
            for k in 0..n {
                if k > 0 {
                    let (from, to) = (u[k - 1], u[k]);
                    for j in 0..2 {
                        let steer = |tau: f64| from + (f64::from(j) + tau) / 2.0 * (to - from);
                        Car::PAPER.rk4_step(theta, 0.01, steer, &mut x);
                    }
                }
                y.push(Car::PAPER.lateral_acceleration(theta, u[k], &x));
            }
            y
        };
        let anchor = [0.5 * (lower[0] + upper[0]), 0.5 * (lower[1] + upper[1])];
        let truth = [-31.0, -1.05];
        let y: Vec<f64> = simulate(truth);
        let h = [1e-4, 1e-6];
        let sens: Vec<Vec<f64>> = (0..2)
            .map(|j| {
                let (mut up, mut down) = (anchor, anchor);
                up[j] += h[j];
                down[j] -= h[j];
                simulate(up)
                    .iter()
                    .zip(simulate(down))
                    .map(|(a, b)| (a - b) / (2.0 * h[j]))
                    .collect()
            })
            .collect();
        let at = simulate(anchor);
        let r: Vec<f64> = y.iter().zip(&at).map(|(a, b)| a - b).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let w = [upper[0] - lower[0], upper[1] - lower[1]];
        let a = dot(&sens[0], &sens[0]) / 0.01 + 4.0 / (w[0] * w[0]);
        let b = dot(&sens[0], &sens[1]) / 0.01;
        let d = dot(&sens[1], &sens[1]) / 0.01 + 4.0 / (w[1] * w[1]);
        let (g0, g1) = (dot(&sens[0], &r) / 0.01, dot(&sens[1], &r) / 0.01);
        let det = a * d - b * b;
        let step = [(d * g0 - b * g1) / det, (a * g1 - b * g0) / det];
        let uu = ndarray::Array2::from_shape_vec((n, 1), u.clone()).unwrap();
        let yy = ndarray::Array2::from_shape_vec((n, 1), y.clone()).unwrap();
        let f = lin.compress(uu.view(), yy.view()).unwrap();
        for j in 0..2 {
            assert!(
                (f[2 + j] * w[j] - step[j]).abs() < 1e-5 * step[j].abs().max(1e-3),
                "{j}: {} against {}",
                f[2 + j] * w[j],
                step[j]
            );
        }
        // One step from the centre lands near the truth on pK1.
        assert!((f[0] - truth[0]).abs() < 1.0, "{f:?}");
        // The dual numbers' output at the anchor is the plain simulation's.
        let mut stream = twostage_kernels::linearized::CarStream::new();
        let car = lin.car().unwrap();
        let (_, r0) = stream.push(car, u[0], y[0]);
        assert_eq!(r0.to_bits(), (y[0] - at[0]).to_bits());
    }

    /// A record's length, shape and finiteness are checked by name.
    #[test]
    fn bad_records_are_refused_and_an_unshaped_one_says_what_to_use() {
        let lin = Linearized::new(1).unwrap();
        let (u, y) = (
            ndarray::Array2::zeros((50, 1)),
            ndarray::Array2::zeros((50, 1)),
        );
        let unshaped = lin.compress(u.view(), y.view()).unwrap_err().to_string();
        assert!(unshaped.contains("arx"), "{unshaped}");
        let lin = lin
            .for_car(Car::PAPER, [-42.0, -1.2], [-28.0, -1.0], 0.01, 0.02)
            .unwrap();
        let mut bad = y.clone();
        bad[[7, 0]] = f64::NAN;
        let nan = lin.compress(u.view(), bad.view()).unwrap_err().to_string();
        assert!(nan.contains("sample 7"), "{nan}");
        let short = ndarray::Array2::zeros((1, 1));
        assert!(lin.compress(short.view(), short.view()).is_err());
        assert!(Linearized::new(0).is_err() && Linearized::new(MAX_SUBSTEPS + 1).is_err());
        // Read back as written; a file that asks for too many steps, or an
        // anchor off the box's centre, is refused.
        let json = serde_json::to_string(&lin).unwrap();
        assert_eq!(serde_json::from_str::<Linearized>(&json).unwrap(), lin);
        let many = json.replacen("\"substeps\":1", "\"substeps\":4000000000", 2);
        assert!(serde_json::from_str::<Linearized>(&many).is_err(), "{many}");
        let off = json.replacen("\"anchor\":[-35.0", "\"anchor\":[-30.0", 1);
        assert_ne!(off, json);
        assert!(serde_json::from_str::<Linearized>(&off).is_err(), "{off}");
        assert!(
            Linearized::new(1)
                .unwrap()
                .for_car(Car::PAPER, [-28.0, -1.2], [-42.0, -1.0], 0.01, 0.02)
                .is_err()
        );
    }
}
