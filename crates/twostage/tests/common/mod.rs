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

/// The line of a model-file error, after asserting that it names `key`
/// and says `text`.
pub fn named_line(e: &twostage::sources::Error, key: &str, text: &str) -> Option<usize> {
    match e {
        twostage::sources::Error::ModelFile {
            key: k,
            line,
            message,
            ..
        } => {
            assert_eq!(k, key, "{e}");
            assert!(message.contains(text), "{e}");
            *line
        }
        other => panic!("{other}"),
    }
}
