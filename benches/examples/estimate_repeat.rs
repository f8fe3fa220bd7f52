//! Estimate one built-in model's record many times, for instruction
//! counts that a noisy machine cannot blur (docs/performance.md):
//!
//! ```sh
//! cargo build --release -p twostage-benches --example estimate_repeat
//! for k in 1 1001; do
//!   valgrind --tool=callgrind target/release/examples/estimate_repeat car.tsest pacejka $k
//! done   # (second total - first total) / 1000 = instructions per estimate
//! ```
//!
//! The record is the criterion group's (benchmark theta = 0.5, car
//! (pK1, pK2) = (-35, -1.1)).

use std::process::ExitCode;

use twostage::models::BuiltinModel;
use twostage::{EstimateWorkspace, Estimator};
use twostage_benches::record;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("estimate_repeat: {message}");
            eprintln!("usage: estimate_repeat ESTIMATOR_FILE benchmark|pacejka REPETITIONS");
            ExitCode::from(2)
        }
    }
}

fn run(args: &[String]) -> Result<(), String> {
    let [file, model, repetitions] = args else {
        return Err("three arguments expected".into());
    };
    let estimator = Estimator::load(file).map_err(|e| e.to_string())?;
    let model: BuiltinModel = model.parse().map_err(|e| format!("{e}"))?;
    let repetitions: usize = repetitions
        .parse()
        .map_err(|e| format!("repetitions: {e}"))?;
    let simulator = model.build().map_err(|e| e.to_string())?;
    let theta: &[f64] = match model {
        BuiltinModel::Benchmark => &[0.5],
        BuiltinModel::Pacejka => &[-35.0, -1.1],
    };
    let data = record(simulator.as_ref(), theta);
    let mut work = EstimateWorkspace::new();
    let mut estimate = vec![0.0; estimator.param_names().len()];
    for _ in 0..repetitions {
        estimator
            .estimate_into(data.inputs(), data.outputs(), &mut work, &mut estimate)
            .map_err(|e| e.to_string())?;
    }
    println!("{estimate:?}");
    Ok(())
}
