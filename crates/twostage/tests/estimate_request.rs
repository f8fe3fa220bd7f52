//! The estimate request every door builds: each way of estimating gives
//! the rows its own method gives alone, windows are the records' own
//! windows, and a request that cannot run is refused by its part.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::baselines::{MethodSettings, classic_estimator};
use twostage::models::{Benchmark, BuiltinModel, IoData, Simulator, experiment_rng};
use twostage::sources::csv_rows::DataFileError;
use twostage::{
    ClassicMethod, EstimateRequest, EstimateWith, Estimator, GivenValues, MethodFailure,
    NamedModel, Purpose, RecordFailure, RefinePolicy, RefineWhich, RequestProblem, Silent,
    TwoStage, Windows,
};

fn estimator() -> Estimator {
    TwoStage::builder(&Benchmark::new())
        .preset(twostage::paper_benchmark())
        .simulations(400)
        .validation(0)
        .calibration(200)
        .seed(3)
        .train()
        .unwrap()
}

fn records(thetas: &[f64], seed: u64) -> Vec<(String, Result<IoData, DataFileError>)> {
    let model = Benchmark::new();
    thetas
        .iter()
        .enumerate()
        .map(|(i, theta)| {
            let mut record = model.spec().new_record();
            model
                .simulate(&[*theta], &mut experiment_rng(seed, i as u64), &mut record)
                .unwrap();
            (format!("e{i}"), Ok(record))
        })
        .collect()
}

#[test]
fn an_estimator_s_rows_are_its_own_estimates_and_windows_the_records_own_windows() {
    let estimator = estimator();
    // Windows of another length than training's are estimated only where
    // a fit through the model follows (here the joint fit).
    let request = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
        .windows(Some(Windows {
            length: 500,
            every: 250,
        }))
        .joint(true);
    let estimating = request.prepare().unwrap();
    assert_eq!(estimating.trained_length(), Some(1000));
    let mut given = records(&[-0.5, 0.4], 5);
    let whole: Vec<IoData> = given.iter().map(|(_, r)| r.clone().unwrap()).collect();
    let unreadable = DataFileError::at("file.csv", 3, "not a number").in_column("y");
    given.push(("bad".into(), Err(unreadable.clone())));
    let estimates = estimating.estimate("file.csv", given, &Silent);
    assert_eq!(estimates.rows.len(), 7);
    for (k, (id, outcome)) in estimates.rows.iter().take(6).enumerate() {
        let (window, row) = outcome.as_ref().unwrap();
        let end = 500 + 250 * (k % 3);
        assert_eq!(
            (id.as_str(), row.window_end),
            (["e0", "e1"][k / 3], Some(end))
        );
        let alone = estimator
            .assess(&whole[k / 3].window(end - 500, end))
            .unwrap();
        assert_eq!(window.n_samples(), 500);
        assert_eq!(row.theta, alone.theta);
        assert_eq!(row.half_widths.as_deref(), alone.interval_half_widths());
    }
    // A record that could not be read is kept as it was said.
    let (id, bad) = estimates.rows.last().unwrap();
    assert_eq!(id, "bad");
    assert!(
        matches!(bad, Err(RecordFailure::Unreadable(e)) if *e == unreadable),
        "{bad:?}"
    );
    assert_eq!(
        bad.as_ref().unwrap_err().to_string(),
        "file.csv: row 3, column y: not a number"
    );
    // The plant gathers the estimated windows, not the unreadable record,
    // and its fit is the joint fit of the same rows.
    let mut plant = estimating.plant();
    plant.gather(&estimates, |id| format!("file.csv: experiment {id}"));
    assert_eq!(plant.len(), 6);
    assert_eq!(plant.places()[3], "file.csv: experiment e1");
    let pairs: Vec<(&IoData, &twostage::RecordEstimate)> = estimates.rows[..6]
        .iter()
        .map(|(_, o)| {
            let (record, row) = o.as_ref().unwrap();
            (record, row)
        })
        .collect();
    let (alone, _) = estimating.joint(&pairs, &Silent).unwrap().unwrap();
    let (gathered, row) = estimating.fit_plant(&plant, &Silent).unwrap().unwrap();
    assert_eq!(gathered.theta, alone.theta);
    assert_eq!(row.theta, alone.theta);
    let unjoined = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
        .prepare()
        .unwrap();
    let mut nothing = unjoined.plant();
    nothing.gather(&estimates, |id| id.to_string());
    assert!(nothing.is_empty(), "no joint fit asked: nothing gathered");
    assert!(unjoined.fit_plant(&nothing, &Silent).is_none());

    // Without a fit that follows, another length is refused by name.
    let estimating = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator)))
        .windows(Some(Windows {
            length: 500,
            every: 500,
        }))
        .prepare()
        .unwrap();
    let estimates = estimating.estimate("file.csv", records(&[0.1], 5), &Silent);
    let refused = estimates.rows[0].1.as_ref().unwrap_err();
    assert!(
        matches!(refused, RecordFailure::NotEstimated { place, why: MethodFailure::Length(_) }
            if place == "file.csv: experiment e0"),
        "{refused:?}"
    );
    let said = refused.to_string();
    assert!(
        said.starts_with("file.csv: experiment e0: ") && said.contains("500 samples"),
        "{said}"
    );
    let short = estimating.estimate(
        "f.csv",
        vec![("s".into(), Ok(whole[0].window(0, 80)))],
        &Silent,
    );
    assert_eq!(
        short.rows[0].1.as_ref().unwrap_err().to_string(),
        "f.csv: experiment s: 80 samples, shorter than the window of 500"
    );
}

#[test]
fn a_classic_method_and_given_values_give_their_own_estimates_and_are_checked() {
    let settings = MethodSettings::default();
    let request = EstimateRequest::new(EstimateWith::Classic {
        method: ClassicMethod::Ekf,
        settings: settings.clone(),
    })
    .model(Some(NamedModel::builtin("benchmark").unwrap()));
    let estimating = request.prepare().unwrap();
    let given = records(&[0.3, -0.2], 9);
    let alone = classic_estimator(BuiltinModel::Benchmark, ClassicMethod::Ekf, &settings).unwrap();
    let estimates = estimating.estimate("f", given.clone(), &Silent);
    for ((_, record), (_, outcome)) in given.iter().zip(&estimates.rows) {
        let (_, row) = outcome.as_ref().unwrap();
        let own = alone.estimate(record.as_ref().unwrap()).unwrap();
        assert_eq!(row.theta, own.theta);
        assert!(row.check.is_none() && row.half_widths.is_none());
    }

    // Given values, one row per experiment, checked against the records
    // they belong to: the truth is explained, a value far off is not.
    let values = GivenValues::new(
        vec![("e0".into(), vec![0.3]), ("e1".into(), vec![0.85])],
        "values.csv",
    )
    .unwrap();
    let request = EstimateRequest::new(EstimateWith::Given(values))
        .model(Some(NamedModel::builtin("benchmark").unwrap()))
        .check_records(true)
        .check_settings(twostage::CheckSettings {
            runs: 99,
            score_from: 0,
            score_to: None,
        });
    let estimating = request.prepare().unwrap();
    let mut with_stranger = given;
    with_stranger.push(("e9".into(), with_stranger[0].1.clone()));
    let estimates = estimating.estimate("f", with_stranger, &Silent);
    let check = |k: usize| {
        let (_, row) = estimates.rows[k].1.as_ref().unwrap();
        row.check.clone().unwrap().unwrap()
    };
    assert!(check(0).explained(), "{:?}", check(0));
    assert!(!check(1).explained(), "{:?}", check(1));
    let stranger = estimates.rows[2].1.as_ref().unwrap_err();
    assert!(
        matches!(
            stranger,
            RecordFailure::NotEstimated {
                why: MethodFailure::Given(_),
                ..
            }
        ),
        "{stranger:?}"
    );
    assert!(
        stranger
            .to_string()
            .contains("values.csv has no row for experiment e9"),
        "{stranger}"
    );
}

#[test]
fn refine_auto_refines_only_what_the_check_does_not_explain() {
    let estimator = estimator();
    let request = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator.clone())))
        .refine(Some(RefineWhich::Auto(RefinePolicy::default())));
    let estimating = request.prepare().unwrap();
    let mut given = records(&[0.2, -0.6], 4);
    // A record of another length: estimated only to start the refinement,
    // which the policy then runs.
    let short = given[0].1.as_ref().unwrap().window(0, 600);
    given.push(("short".into(), Ok(short)));
    let estimates = estimating.estimate("f", given, &Silent);
    let auto = estimates.auto.clone().unwrap();
    assert_eq!(auto.checked, 3);
    assert!(auto.reasons[2].is_some(), "{auto:?}");
    for (k, reason) in auto.reasons.iter().enumerate() {
        let (_, row) = estimates.rows[k].1.as_ref().unwrap();
        // Refined rows say so; the others keep their two-stage estimate.
        assert_eq!(row.refinement.is_some(), reason.is_some(), "row {k}");
        assert!(row.check.is_some());
    }
    let groups = auto.groups(&estimates.rows);
    assert!(groups.iter().any(|(_, ids)| ids.contains(&"short")));
}

#[test]
fn a_request_that_cannot_run_is_refused_by_its_part() {
    let refused = |request: EstimateRequest| request.prepare().err().unwrap();
    let e = refused(EstimateRequest::new(EstimateWith::OutputError {
        starts: 3,
    }));
    assert_eq!(e.purpose, Purpose::OutputError);
    assert!(matches!(e.error, RequestProblem::NoModel));
    let e = refused(
        EstimateRequest::new(EstimateWith::OutputError { starts: 3 })
            .refine(Some(RefineWhich::All))
            .model(Some(NamedModel::builtin("benchmark").unwrap())),
    );
    assert_eq!(e.purpose, Purpose::Refine);
    assert!(matches!(e.error, RequestProblem::NeedsEstimator));
    let e = refused(
        EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator()))).windows(Some(
            Windows {
                length: 100,
                every: 0,
            },
        )),
    );
    assert_eq!(e.purpose, Purpose::Windows);
    assert!(e.to_string().contains("at least 1 sample"), "{e}");
    // The car has no EKF in the paper's table: the method's own words.
    let e = refused(
        EstimateRequest::new(EstimateWith::Classic {
            method: ClassicMethod::Ekf,
            settings: MethodSettings::default(),
        })
        .model(Some(NamedModel::builtin("pacejka").unwrap())),
    );
    assert_eq!(e.purpose, Purpose::Method);
    assert!(
        e.to_string().contains("'ekf' is not available for pacejka"),
        "{e}"
    );
    // A model file is not its built-in source, even of the same name: its
    // settings are its own, and a classic method is the built-in's.
    let file = NamedModel::text(
        "[model]\nname = \"benchmark\"\n[source]\nbuiltin = \"benchmark\"\n",
        "benchmark.toml",
    )
    .unwrap();
    let e = refused(
        EstimateRequest::new(EstimateWith::Classic {
            method: ClassicMethod::Ekf,
            settings: MethodSettings::default(),
        })
        .model(Some(file)),
    );
    assert_eq!(e.purpose, Purpose::Method);
    assert!(matches!(e.error, RequestProblem::NotBuiltIn { .. }), "{e}");
    // A trained estimator reads a model only to check, refine or fit
    // jointly: given without them, it is refused, not ignored.
    let trained = estimator();
    let with_model = || {
        EstimateRequest::new(EstimateWith::Estimator(Box::new(trained.clone())))
            .model(Some(NamedModel::builtin("benchmark").unwrap()))
    };
    let e = refused(with_model());
    assert_eq!(e.purpose, Purpose::Model);
    assert!(matches!(e.error, RequestProblem::ModelNotRead), "{e}");
    assert!(with_model().check_records(true).prepare().is_ok());
    assert!(with_model().joint(true).prepare().is_ok());
}
