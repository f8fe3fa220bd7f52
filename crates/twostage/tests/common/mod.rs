//! What several integration tests of the facade share.
#![allow(dead_code, clippy::unwrap_used)]

use std::fmt::Write as _;
use std::path::Path;

use twostage::models::{Benchmark, IoData, Simulator, run_experiment};

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

/// Experiments 0..m of the design of `seed` of `model` (one input, one
/// output), written as `twostage simulate
/// --count` does (values that read back to the same bits).
pub fn write_chart(model: &Benchmark, dir: &Path, m: usize, seed: u64) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let design = model.prior().design(m, seed).unwrap();
    let (mut truth, mut data) = (
        String::from("experiment,theta\n"),
        String::from("experiment,u,y\n"),
    );
    let (mut theta, mut record) = ([0.0], IoData::default());
    for i in 0..m {
        run_experiment(model, &design, i, &mut theta, &mut record).unwrap();
        writeln!(truth, "{i},{:?}", theta[0]).unwrap();
    }
    // data.csv in reverse: experiments may come in any order.
    for i in (0..m).rev() {
        run_experiment(model, &design, i, &mut theta, &mut record).unwrap();
        for k in 0..record.n_samples() {
            let (u, y) = (record.input(0)[k], record.output(0)[k]);
            writeln!(data, "{i},{u:?},{y:?}").unwrap();
        }
    }
    std::fs::write(dir.join("truth.csv"), truth).unwrap();
    std::fs::write(dir.join("data.csv"), data).unwrap();
}
