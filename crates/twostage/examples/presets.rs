//! Train both paper presets at full size and print their validation reports.
//!
//! `cargo run --release -p twostage --example presets`

use std::time::Instant;

use twostage::TwoStage;
use twostage::models::{Benchmark, PacejkaCar};

fn main() -> Result<(), twostage::Error> {
    let bench = Benchmark::new();
    let start = Instant::now();
    let estimator = TwoStage::builder(&bench)
        .preset(twostage::paper_benchmark())
        .validation(2000)
        .calibration(1000)
        .seed(1)
        .train()?;
    println!(
        "benchmark preset trained and validated in {:.2?}",
        start.elapsed()
    );
    if let Some(report) = estimator.validation() {
        println!("{report}");
    }
    if let twostage::FittedRegressor::Mlp(net) = estimator.regressor() {
        for r in net.reports() {
            println!("  restart {r:?}");
        }
    }
    let car = PacejkaCar::new();
    let start = Instant::now();
    let estimator = TwoStage::builder(&car)
        .preset(twostage::paper_pacejka())
        .validation(800)
        .calibration(500)
        .seed(1)
        .train()?;
    println!(
        "car preset trained and validated in {:.2?}",
        start.elapsed()
    );
    if let Some(report) = estimator.validation() {
        println!("{report}");
    }
    Ok(())
}
