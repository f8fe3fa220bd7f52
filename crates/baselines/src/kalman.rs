//! The exact Kalman filter of the benchmark at a known theta: the benchmark
//! is linear and Gaussian given theta, so this filter gives the optimal
//! one-step predictor and the exact likelihood of a record.

use twostage_models::{Benchmark, IoData, MEASUREMENT_NOISE_VARIANCE, PROCESS_NOISE_VARIANCE};

use crate::error::{BaselineError, Result};

/// The benchmark of eq. (5) at one theta as a state-space model
/// `x(k+1) = A x(k) + B u(k) + w(k)`, `y(k) = x2(k) + v(k)`, with
/// `w ~ N(0, I)`, `v ~ N(0, 0.1)`, `x(0) = 0` known exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchmarkStateSpace {
    /// `A = [[1/2, 0], [a, -theta]]`.
    pub a: [[f64; 2]; 2],
    /// `B = [1, b]`.
    pub b: [f64; 2],
    /// Process noise variance (each of v11, v12).
    pub q: f64,
    /// Measurement noise variance.
    pub r: f64,
}

impl BenchmarkStateSpace {
    /// The model at `theta`.
    pub fn at(theta: f64) -> Self {
        let (a, b) = Benchmark::coefficients(theta);
        Self {
            a: [[0.5, 0.0], [a, -theta]],
            b: [1.0, b],
            q: PROCESS_NOISE_VARIANCE,
            r: MEASUREMENT_NOISE_VARIANCE,
        }
    }
}

/// The input and output of a benchmark record, checked: one of each, finite.
pub(crate) fn benchmark_signals(record: &IoData) -> Result<(&[f64], &[f64])> {
    if record.n_inputs() != 1 || record.n_outputs() != 1 {
        return Err(BaselineError::Shape {
            what: "the record's inputs and outputs",
            found: format!("{} and {}", record.n_inputs(), record.n_outputs()),
            expected: "one of each (the benchmark is SISO)".into(),
        });
    }
    record.check_finite()?;
    Ok((record.input(0), record.output(0)))
}

/// What the Kalman filter says of one record.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanRun {
    /// Log-likelihood `ln p(y(0..N) | u, theta)`.
    pub log_likelihood: f64,
    /// Sum of squared innovations (the prediction-error loss).
    pub sum_squared_innovations: f64,
}

/// Run the exact Kalman filter of the benchmark at `theta` over a SISO
/// record: update with y(k), then predict with u(k), from x(0|-1) = 0 and
/// P(0|-1) = 0.
///
/// ```
/// use twostage_baselines::benchmark_kalman;
/// use twostage_models::{experiment_rng, Benchmark, Simulator};
/// let model = Benchmark::new();
/// let mut record = model.spec().new_record();
/// model.simulate(&[0.6], &mut experiment_rng(3, 0), &mut record)?;
/// let at_truth = benchmark_kalman(0.6, &record)?.log_likelihood;
/// let elsewhere = benchmark_kalman(-0.2, &record)?.log_likelihood;
/// assert!(at_truth > elsewhere);
/// # Ok::<(), twostage_baselines::BaselineError>(())
/// ```
///
/// # Errors
/// A record that is not SISO or holds non-finite samples.
pub fn benchmark_kalman(theta: f64, record: &IoData) -> Result<KalmanRun> {
    benchmark_kalman_innovations(theta, record, None)
}

/// As [`benchmark_kalman`], also writing the innovations `y(k) - y_hat(k|k-1)`
/// (the one-step prediction errors) into `innovations` when given.
///
/// # Errors
/// As [`benchmark_kalman`], and an `innovations` buffer of the wrong length.
pub fn benchmark_kalman_innovations(
    theta: f64,
    record: &IoData,
    mut innovations: Option<&mut [f64]>,
) -> Result<KalmanRun> {
    if let Some(buffer) = &innovations
        && buffer.len() != record.n_samples()
    {
        return Err(BaselineError::Shape {
            what: "the innovation buffer",
            found: format!("{} slots", buffer.len()),
            expected: format!("one per sample ({})", record.n_samples()),
        });
    }
    let (u, y) = benchmark_signals(record)?;
    let m = BenchmarkStateSpace::at(theta);
    let mut x = [0.0f64; 2];
    let mut p = [[0.0f64; 2]; 2];
    let mut log_likelihood = 0.0;
    let mut sse = 0.0;
    let ln_2pi = (2.0 * std::f64::consts::PI).ln();
    for (k, (&uk, &yk)) in u.iter().zip(y).enumerate() {
        // Update with y(k): C = [0, 1].
        let s = p[1][1] + m.r;
        if s.is_nan() || s <= 0.0 {
            return Err(BaselineError::Numerical {
                sample: k,
                what: format!("innovation variance {s}"),
            });
        }
        let e = yk - x[1];
        let gain = [p[0][1] / s, p[1][1] / s];
        x = [x[0] + gain[0] * e, x[1] + gain[1] * e];
        let p01 = p[0][1];
        let p11 = p[1][1];
        p = [
            [p[0][0] - gain[0] * p01, p[0][1] - gain[0] * p11],
            [p[1][0] - gain[1] * p01, p[1][1] - gain[1] * p11],
        ];
        log_likelihood -= 0.5 * (ln_2pi + s.ln() + e * e / s);
        sse += e * e;
        if let Some(buffer) = innovations.as_deref_mut() {
            buffer[k] = e;
        }
        // Predict with u(k): x = A x + B u, P = A P A' + Q.
        let a = m.a;
        x = [
            a[0][0] * x[0] + a[0][1] * x[1] + m.b[0] * uk,
            a[1][0] * x[0] + a[1][1] * x[1] + m.b[1] * uk,
        ];
        let ap = [
            [
                a[0][0] * p[0][0] + a[0][1] * p[1][0],
                a[0][0] * p[0][1] + a[0][1] * p[1][1],
            ],
            [
                a[1][0] * p[0][0] + a[1][1] * p[1][0],
                a[1][0] * p[0][1] + a[1][1] * p[1][1],
            ],
        ];
        p = [
            [
                ap[0][0] * a[0][0] + ap[0][1] * a[0][1] + m.q,
                ap[0][0] * a[1][0] + ap[0][1] * a[1][1],
            ],
            [
                ap[1][0] * a[0][0] + ap[1][1] * a[0][1],
                ap[1][0] * a[1][0] + ap[1][1] * a[1][1] + m.q,
            ],
        ];
    }
    Ok(KalmanRun {
        log_likelihood,
        sum_squared_innovations: sse,
    })
}
