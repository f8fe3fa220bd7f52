//! The validation run every door makes: its sizes, its rounds, its
//! refusals, and that its report is the rows' own.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::models::Benchmark;
use twostage::validate::{hoeffding_sample_size, squared_error_bound};
use twostage::{Estimator, Silent, TargetRmse, TwoStage, ValidationPlan, validate_estimator};

fn estimator(model: &Benchmark) -> Estimator {
    TwoStage::builder(model)
        .compressor("arx:2,2".parse::<twostage::CompressorConfig>().unwrap())
        .regressor("linear".parse().unwrap())
        .simulations(300)
        .validation(0)
        .calibration(0)
        .seed(3)
        .train()
        .unwrap()
}

fn plan(sims: usize) -> ValidationPlan {
    ValidationPlan {
        sims: Some(sims),
        seed: 11,
        ..ValidationPlan::default()
    }
}

#[test]
fn a_grown_run_stops_at_the_first_round_that_meets_the_target_and_equals_a_run_of_that_size() {
    let model = Benchmark::new();
    let estimator = estimator(&model);
    let grown = ValidationPlan {
        target_rmse: Some(1.5),
        ..plan(100)
    };
    let run = validate_estimator(&estimator, &model, &grown, &Silent).unwrap();
    let Some(TargetRmse::Met { ratio }) = run.target else {
        panic!("{:?}", run.target)
    };
    let r = run.records;
    assert!(r > 100 && run.rounds.first() == Some(&100) && run.rounds.last() == Some(&r));
    assert!(
        run.rounds.windows(2).all(|w| w[1] >= w[0] + w[0] / 2),
        "{:?}",
        run.rounds
    );
    assert!(ratio <= 1.5);
    // Each round extends the one before: the same records, bit for bit,
    // as a run of the final size, and the round before it fell short.
    let fixed = validate_estimator(&estimator, &model, &plan(r), &Silent).unwrap();
    assert_eq!(fixed.truth, run.truth);
    assert_eq!(fixed.estimates, run.estimates);
    assert_eq!(fixed.report.certified_ratio().to_bits(), ratio.to_bits());
    let previous = run.rounds[run.rounds.len() - 2];
    let before = validate_estimator(&estimator, &model, &plan(previous), &Silent).unwrap();
    assert!(before.report.certified_ratio() > 1.5);
    assert_eq!(before.truth[..], fixed.truth[..before.truth.len()]);

    // Out of room: said, with the ratio reached.
    let short = ValidationPlan {
        target_rmse: Some(1.01),
        max_sims: 300,
        ..plan(100)
    };
    let run = validate_estimator(&estimator, &model, &short, &Silent).unwrap();
    assert_eq!(run.records, 300);
    assert!(matches!(run.target, Some(TargetRmse::NotMet { ratio }) if ratio > 1.01));
}

#[test]
fn the_report_is_the_rows_own_and_gamma_sizes_the_run_by_theorem_1() {
    let model = Benchmark::new();
    let estimator = estimator(&model);
    let run = validate_estimator(&estimator, &model, &plan(250), &Silent).unwrap();
    assert_eq!(run.truth.len(), 250);
    let mse = run
        .truth
        .iter()
        .zip(&run.estimates)
        .map(|(t, e)| (t - e).powi(2))
        .sum::<f64>()
        / 250.0;
    assert!((run.report.parameters[0].mse - mse).abs() <= 1e-12 * mse);
    // The truths are the prior's: inside the box, and spread over it.
    let (lo, hi) = (estimator.lower()[0], estimator.upper()[0]);
    assert!(run.truth.iter().all(|t| (lo..=hi).contains(t)));
    let mean = run.truth.iter().sum::<f64>() / 250.0;
    assert!((mean - (lo + hi) / 2.0).abs() < 0.1 * (hi - lo), "{mean}");

    // By hand, the paper's eq. (4): the smallest r above
    // sigma^2 / (2 gamma^2) ln(1 / delta).
    let sigma = squared_error_bound(estimator.lower(), estimator.upper());
    let (gamma, delta) = (0.3, 0.01);
    let bound = sigma * sigma * (1.0_f64 / delta).ln() / (2.0 * gamma * gamma);
    let r = hoeffding_sample_size(sigma, gamma, delta).unwrap();
    assert_eq!(r, bound.floor() as u64 + 1, "{r} against {bound}");
    let sized = ValidationPlan {
        sims: None,
        gamma: Some(gamma),
        delta,
        ..plan(0)
    };
    let run = validate_estimator(&estimator, &model, &sized, &Silent).unwrap();
    assert_eq!(run.records as u64, r);
}

#[test]
fn a_plan_out_of_range_is_refused_by_its_setting() {
    let model = Benchmark::new();
    let estimator = estimator(&model);
    let refused = |plan: ValidationPlan, name: &str, says: &str| {
        let e = validate_estimator(&estimator, &model, &plan, &Silent).unwrap_err();
        assert!(e.is_setting(), "{e}");
        let text = e.to_string();
        assert!(text.contains(name) && text.contains(says), "{text}");
    };
    refused(plan(0), "sims = 0", "at least 1");
    refused(
        ValidationPlan {
            target_rmse: Some(0.9),
            ..plan(100)
        },
        "target_rmse = 0.9",
        "give a multiple above 1",
    );
    refused(
        ValidationPlan {
            target_rmse: Some(f64::NAN),
            ..plan(100)
        },
        "target_rmse = NaN",
        "above 1",
    );
    refused(
        ValidationPlan {
            target_rmse: Some(2.0),
            max_sims: 50,
            ..plan(100)
        },
        "max_sims = 50",
        "first round of 100",
    );
    refused(
        ValidationPlan {
            gamma: Some(0.1),
            ..plan(100)
        },
        "gamma",
        "give one",
    );
    refused(
        ValidationPlan {
            delta: 1.5,
            ..plan(100)
        },
        "delta = 1.5",
        "between 0 and 1",
    );
    refused(
        ValidationPlan {
            sims: None,
            gamma: Some(-1.0),
            ..plan(100)
        },
        "gamma",
        "> 0",
    );
}
