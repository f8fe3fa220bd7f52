//! The Rust side of the Python batch measurement (docs/performance.md,
//! crates/python/bench/batch_cost.py): estimate every record of a `.npy`
//! chart with `Estimator::estimate_batch` (parallel over the records) and
//! print the best wall time of five runs in seconds.
//!
//! ```sh
//! cargo run --release -p twostage-benches --example batch_cost -- EST.tsest CHART_DIR
//! ```

use std::process::ExitCode;
use std::time::Instant;

use twostage::models::IoData;
use twostage::{ChartFiles, Estimator, NamedModel};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(seconds) => {
            println!("{seconds:.6}");
            ExitCode::SUCCESS
        }
        Err(message) => {
            eprintln!("batch_cost: {message}");
            eprintln!("usage: batch_cost ESTIMATOR_FILE CHART_DIR (a benchmark chart)");
            ExitCode::from(2)
        }
    }
}

fn run(args: &[String]) -> Result<f64, String> {
    let [file, chart] = args else {
        return Err("two arguments expected".into());
    };
    let estimator = Estimator::load(file).map_err(|e| e.to_string())?;
    let model = NamedModel::builtin(&estimator.training().model).map_err(|e| e.to_string())?;
    let simulator = model.chart_model().map_err(|e| e.to_string())?;
    let chart = ChartFiles::open(chart, simulator.spec()).map_err(|e| e.to_string())?;
    let mut records: Vec<IoData> = Vec::with_capacity(chart.len());
    chart
        .for_each_record(simulator.spec(), |_, record| {
            records.push(record.clone());
            Ok(())
        })
        .map_err(|e| e.to_string())?;
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let start = Instant::now();
        let estimates = estimator.estimate_batch(&records);
        let seconds = start.elapsed().as_secs_f64();
        if let Some(Err(e)) = estimates.iter().find(|e| e.is_err()) {
            return Err(e.to_string());
        }
        std::hint::black_box(estimates);
        best = best.min(seconds);
    }
    Ok(best)
}
