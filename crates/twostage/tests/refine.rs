//! The refinement of an estimate against closed forms: on a model whose
//! loss is `sum (y_k - theta)^2` the minimizer is the sample mean and, under
//! a flat prior, the posterior is Gaussian with mean y_bar and sd s/sqrt(n).

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::models::{IoData, Prior};
use twostage::{Error, RefineError, RefineStarts, Refinement, ResidualModel};

/// y_k = theta + noise.
struct ConstantMean {
    prior: Prior,
}

impl ResidualModel for ConstantMean {
    type Error = Error;
    fn prior(&self) -> &Prior {
        &self.prior
    }
    fn residuals(
        &self,
        theta: &[f64],
        record: &IoData,
        residuals: &mut [f64],
    ) -> twostage::Result<()> {
        for (r, y) in residuals.iter_mut().zip(record.output(0)) {
            *r = y - theta[0];
        }
        Ok(())
    }
}

/// 400 deterministic values around 1.3, their mean and the posterior sd.
fn data() -> (IoData, f64, f64) {
    let n = 400;
    let y: Vec<f64> = (0..n)
        .map(|k| 1.3 + ((k * 7919 + 11) % 101) as f64 / 50.0 - 1.0)
        .collect();
    let mean = y.iter().sum::<f64>() / n as f64;
    let loss_min: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let sd = (loss_min / n as f64).sqrt() / (n as f64).sqrt();
    (IoData::siso(&vec![0.0; n], &y).unwrap(), mean, sd)
}

fn model(lower: f64, upper: f64) -> Refinement<ConstantMean> {
    Refinement::new(ConstantMean {
        prior: Prior::uniform_box(&[lower], &[upper]).unwrap(),
    })
}

#[test]
fn the_local_posterior_of_a_gaussian_mean_is_the_closed_form() {
    let (data, mean, sd) = data();
    let local = model(-10.0, 10.0);
    // A grid centred off the mean, wide enough to hold the posterior.
    let posterior = local
        .local_posterior(&data, &[mean + sd], &[8.0 * sd], 401)
        .unwrap();
    assert!(
        (posterior.mean[0] - mean).abs() < 1e-3 * sd,
        "{posterior:?} vs {mean}"
    );
    assert!(
        (posterior.sd[0] / sd - 1.0).abs() < 0.01,
        "{posterior:?} vs {sd}"
    );
    assert_eq!(posterior.evaluations, 401);
}

#[test]
fn a_descent_ends_at_the_sample_mean_or_at_the_face_of_its_box() {
    let (data, mean, _) = data();
    let local = model(-10.0, 10.0);
    let free = local.descend(&data, vec![-3.0]).unwrap();
    assert!((free.theta[0] - mean).abs() < 1e-8, "{free:?} vs {mean}");
    let expected_loss: f64 = data.output(0).iter().map(|y| (y - mean).powi(2)).sum();
    assert!((free.loss - expected_loss).abs() < 1e-9 * expected_loss);
    // Confined to start +- radius below the mean: it stops at the upper face.
    let start = mean - 0.5;
    for starts in [RefineStarts::Centre, RefineStarts::CentreAndAxes] {
        let capped = local.refine(&data, &[start], &[0.2], starts).unwrap();
        assert!(
            (capped.theta[0] - (start + 0.2)).abs() < 1e-12,
            "{capped:?}"
        );
    }
    // The prior box caps it too: the mean (1.3) lies above [-1, 1].
    let boxed = model(-1.0, 1.0).descend(&data, vec![0.0]).unwrap();
    assert_eq!(boxed.theta, [1.0]);
}

#[test]
fn bad_neighbourhoods_are_named() {
    let (data, mean, _) = data();
    let local = model(-10.0, 10.0);
    let message = |e: Error| e.to_string();
    let e = local
        .refine(&data, &[mean, 0.0], &[1.0], RefineStarts::Centre)
        .unwrap_err();
    assert!(
        matches!(
            e,
            Error::Refine(RefineError::Length {
                what: "the centre",
                found: 2,
                expected: 1
            })
        ),
        "{e}"
    );
    let e = local
        .refine(&data, &[mean], &[f64::NAN], RefineStarts::Centre)
        .unwrap_err();
    assert!(message(e).contains("every radius >= 0"));
    let e = local
        .local_posterior(&data, &[mean], &[1.0], 1)
        .unwrap_err();
    assert!(message(e).contains("points per axis"));
    let e = local.descend(&data, vec![]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Refine(RefineError::Length {
                what: "the start",
                found: 0,
                expected: 1
            })
        ),
        "{e}"
    );
    let e = model(-10.0, 10.0)
        .max_iterations(0)
        .descend(&data, vec![0.0])
        .unwrap_err();
    assert!(message(e).contains("iterations per descent"));
}

/// A model that cannot predict anywhere gives no posterior, and says so.
struct Diverges(Prior);

impl ResidualModel for Diverges {
    type Error = Error;
    fn prior(&self) -> &Prior {
        &self.0
    }
    fn residuals(&self, _: &[f64], _: &IoData, residuals: &mut [f64]) -> twostage::Result<()> {
        residuals.fill(f64::INFINITY);
        Ok(())
    }
}

#[test]
fn a_loss_that_is_nowhere_finite_is_an_error_not_a_nan_mean() {
    let (data, _, _) = data();
    let local = Refinement::new(Diverges(Prior::uniform_box(&[0.0], &[1.0]).unwrap()));
    let e = local.local_posterior(&data, &[0.5], &[0.1], 5).unwrap_err();
    assert!(
        matches!(e, Error::Refine(RefineError::Numerical { .. })),
        "{e}"
    );
}

#[test]
fn an_estimator_without_intervals_has_no_neighbourhood_to_refine_in() {
    use twostage::TwoStage;
    use twostage::models::Benchmark;
    let estimator = TwoStage::builder(&Benchmark::new())
        .preset(twostage::paper_benchmark())
        .simulations(200)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap();
    let e = estimator.neighbourhood(2.0).unwrap_err().to_string();
    assert!(e.contains("calibration > 0"), "{e}");
    let calibrated = TwoStage::builder(&Benchmark::new())
        .preset(twostage::paper_benchmark())
        .simulations(200)
        .validation(0)
        .calibration(50)
        .train()
        .unwrap();
    for scale in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(calibrated.neighbourhood(scale).is_err(), "{scale}");
    }
    assert!(calibrated.neighbourhood(1.5).unwrap()[0] > 0.0);
}
