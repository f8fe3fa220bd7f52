//! Parameters held at values (`--fix`): a smaller estimator whose file
//! says what was held, and whose model, wherever a request finds it,
//! holds it too.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::models::{FixedValues, PacejkaCar, Simulator, experiment_rng};
use twostage::{
    Estimator, EstimatorModel, NamedModel, RecordsRequest, RunSettings, Silent, TrainingRequest,
};

fn request(fix: &[&str]) -> TrainingRequest {
    TrainingRequest {
        simulations: Some(300),
        settings: RunSettings {
            calibration: 200,
            ..RunSettings::default().validation_asked(Some(200), None, None)
        },
        fix: FixedValues::parse(fix).unwrap(),
        ..TrainingRequest::default()
    }
}

#[test]
fn a_held_parameter_leaves_the_estimator_and_stays_held_through_its_file_and_model() {
    let car = NamedModel::builtin("pacejka").unwrap();
    let trained = request(&["pK2=-1.05"]).train(&car, &Silent).unwrap();
    let estimator = trained.estimator();
    assert_eq!(estimator.param_names(), ["pK1".to_string()]);
    assert_eq!(estimator.fixed().to_string(), "pK2 = -1.05");
    assert_eq!(estimator.validation().unwrap().parameters.len(), 1);

    // The file is of format 10 and reads back to the same estimator.
    let bytes = estimator.to_bytes().unwrap();
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 10);
    let read = Estimator::from_bytes(&bytes).unwrap();
    assert_eq!(&read, estimator);
    assert!(read.to_json().unwrap().contains("\"fixed\""));

    // The model every request finds through the estimator holds pK2: its
    // records are the car's at the whole vector, and the car's exact
    // likelihood (of both parameters) is not used to refine it.
    let model = EstimatorModel::find(&read, None).unwrap();
    assert_eq!(model.exact_likelihood(), None);
    let simulator = model.simulator().unwrap();
    assert_eq!(simulator.param_names(), ["pK1".to_string()]);
    let whole = PacejkaCar::new();
    let (mut held, mut expected) = (whole.spec().new_record(), whole.spec().new_record());
    simulator
        .simulate(&[-35.0], &mut experiment_rng(2, 5), &mut held)
        .unwrap();
    whole
        .simulate(&[-35.0, -1.05], &mut experiment_rng(2, 5), &mut expected)
        .unwrap();
    assert_eq!(held, expected);

    // Without a value held the file is what it always was: format 6.
    let free = request(&[]).train(&car, &Silent).unwrap();
    let bytes = free.estimator().to_bytes().unwrap();
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 6);
    assert!(free.estimator().fixed().is_empty());
}

#[test]
fn a_hold_the_records_cannot_honour_is_refused_before_any_work() {
    let car = NamedModel::builtin("pacejka").unwrap();
    let chart = TrainingRequest {
        records: RecordsRequest::chart("no-such-chart"),
        ..request(&["pK2=-1.05"])
    };
    let e = chart.train(&car, &Silent).unwrap_err().to_string();
    assert!(e.contains("simulated at their own values"), "{e}");
    let e = request(&["mass=1500"])
        .train(&car, &Silent)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no parameter 'mass'") && e.contains("pK1, pK2"),
        "{e}"
    );
}
