//! A stage 1 that linearizes the model (`linearized`), as a user trains,
//! saves and reads it: the car's equations reach it from the model (built
//! in, or a model file of it), the file says so by its version, and a
//! model whose equations twostage does not hold is refused with what to
//! use instead.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::models::{Benchmark, InputSignal, PacejkaCar, Simulator, experiment_rng};
use twostage::{CompressorConfig, Estimator, ModelFile, TwoStage};

fn short_car() -> PacejkaCar {
    // Three seconds of a sine steer: a short record the tests can afford.
    let steer = (0..150)
        .map(|k| 0.12 * (k as f64 * 0.02 * 3.0).sin())
        .collect::<Vec<_>>();
    PacejkaCar::builder()
        .n_samples(150)
        .input(InputSignal::fixed(steer).unwrap())
        .build()
        .unwrap()
}

fn trained(model: &dyn Simulator, compressor: &str) -> Estimator {
    TwoStage::builder(model)
        .compressor(compressor.parse::<CompressorConfig>().unwrap())
        .regressor("mlp:8".parse().unwrap())
        .simulations(300)
        .calibration(100)
        .validation(200)
        .seed(4)
        .train()
        .unwrap()
}

#[test]
fn the_car_linearized_is_stored_in_format_8_and_reads_back_the_same() {
    let car = short_car();
    let estimator = trained(&car, "linearized");
    let bytes = estimator.to_bytes().unwrap();
    assert_eq!(bytes[8..12], 8u32.to_le_bytes());
    let back = Estimator::from_bytes(&bytes).unwrap();
    assert_eq!(back, estimator);
    let mut record = car.spec().new_record();
    car.simulate(&[-31.0, -1.05], &mut experiment_rng(9, 0), &mut record)
        .unwrap();
    let (a, b) = (
        estimator.estimate_record(&record).unwrap(),
        back.estimate_record(&record).unwrap(),
    );
    assert_eq!(a[0].to_bits(), b[0].to_bits());
    // What the record says of pK1 reaches the estimate: on 300 records
    // it is far inside the prior's spread, and nearer the truth than an
    // ARX(2, 2) stage 1's with the same stage 2 and records.
    let report = estimator.validation().unwrap();
    let prior_sd = (-27.32 - -42.83) / 12f64.sqrt();
    let arx = trained(&car, "arx:2,2").validation().unwrap().parameters[0].rmse;
    let ours = report.parameters[0].rmse;
    assert!(
        ours < 0.3 * prior_sd && ours < arx,
        "RMSE {ours}, ARX {arx}, prior sd {prior_sd}"
    );
}

#[test]
fn a_model_without_the_cars_equations_is_refused_with_what_to_use() {
    let model = Benchmark::builder().n_samples(200).build().unwrap();
    let refused = TwoStage::builder(&model)
        .compressor("linearized".parse::<CompressorConfig>().unwrap())
        .simulations(100)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("benchmark") && refused.contains("arx"),
        "{refused}"
    );
}

#[test]
fn a_model_file_of_the_car_keeps_its_equations_unless_its_parameters_change() {
    let file = |parameters: &str| {
        format!(
            "[model]\nname = \"my-car\"\n[source]\nbuiltin = \"pacejka\"\n[signals]\nsamples = \
             120\n{parameters}"
        )
    };
    let own = ModelFile::parse(&file(""), "car.toml").unwrap();
    let equations = own.simulator().unwrap().spec().car_equations().copied();
    assert_eq!(
        equations.map(|e| e.noise_variance),
        Some(twostage::models::PACEJKA_NOISE_VARIANCE)
    );
    let renamed = file(
        "[[parameter]]\nname = \"a\"\nprior = { dist = \"uniform\", low = -42.83, high = -27.32 }\n\
         [[parameter]]\nname = \"b\"\nprior = { dist = \"uniform\", low = -1.22, high = -0.98 }\n",
    );
    match ModelFile::parse(&renamed, "renamed.toml") {
        Ok(file) => assert!(file.simulator().unwrap().spec().car_equations().is_none()),
        // A built-in model's parameters may not be renamed at all: then
        // nothing can carry the equations to a stage 1 either.
        Err(refused) => assert!(refused.to_string().contains("parameter"), "{refused}"),
    }
}
