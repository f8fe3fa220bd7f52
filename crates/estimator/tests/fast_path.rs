//! The estimate's fast path (one Cholesky solve on stored normal
//! equations) against the estimate through QR's coefficients.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::TwoStage;
use twostage::compress::{Arx, Compressor};
use twostage::estimator::space::to_estimate;
use twostage::fit::Predictor;
use twostage::models::{IoData, PacejkaCar, Simulator, experiment_rng};
use twostage_estimator::EstimateWorkspace;

#[test]
fn the_fast_path_estimates_as_the_qr_solution_on_the_car() {
    // The car's chicane makes the paper's ARX(4, 4) regressors nearly
    // collinear; the fast path refines them, and the estimate agrees
    // with the one through QR's coefficients to 1e-9.
    let car = PacejkaCar::new();
    let estimator = TwoStage::builder(&car)
        .compressor(Arx::new(4, 4).unwrap())
        .simulations(200)
        .validation(0)
        .calibration(0)
        .seed(5)
        .linear(1e-6)
        .unwrap()
        .train()
        .unwrap();
    let mut work = EstimateWorkspace::new();
    let mut record = IoData::default();
    for i in 0..5u64 {
        let theta = [-26.0 - 3.0 * i as f64, -0.95 - 0.04 * i as f64];
        car.simulate(&theta, &mut experiment_rng(9, i), &mut record)
            .unwrap();
        let mut fast = [0.0; 2];
        estimator
            .estimate_into(record.inputs(), record.outputs(), &mut work, &mut fast)
            .unwrap();
        let features = estimator
            .compressor()
            .compress(record.inputs(), record.outputs())
            .unwrap();
        let mut exact = [0.0; 2];
        estimator
            .regressor()
            .predict_into(&features, &mut exact)
            .unwrap();
        to_estimate(
            &mut exact,
            estimator.marginals(),
            estimator.lower(),
            estimator.upper(),
        );
        for (f, e) in fast.iter().zip(&exact) {
            assert!((f - e).abs() <= 1e-9 * e.abs(), "{fast:?} vs {exact:?}");
        }
    }
}
