//! What several integration tests of the facade share.
#![allow(dead_code, clippy::unwrap_used)]

use twostage::models::Simulator;

/// The validation RMSE of the paper's benchmark preset trained on `m`
/// simulations of `sim` and validated on `r`.
pub fn paper_rmse(sim: &dyn Simulator, m: usize, r: usize, seed: u64) -> f64 {
    twostage::TwoStage::builder(sim)
        .preset(twostage::paper_benchmark())
        .simulations(m)
        .validation(r)
        .calibration(0)
        .seed(seed)
        .train()
        .unwrap()
        .validation()
        .unwrap()
        .parameters[0]
        .rmse
}
