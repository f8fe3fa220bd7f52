//! A Duffing-type oscillator whose output-error loss has several basins:
//! the check must not call an estimate in a wrong basin explained because
//! a descent beside it stops there too (issue 49's first item).

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::{Duffing, record};
use twostage_models::Simulator;
use twostage_refine::{CheckPlan, OutputError, Refinement, check_with};

/// The check of a Duffing record at the estimate of the wrong basin: a
/// descent from a start far off (k = 5.8, as a weak estimator might give)
/// ends in an interior local minimum whose fit is poor. A descent beside
/// it stops there too, so a local check called it explained; the search
/// from the prior finds the truth's basin and says it is not.
#[test]
fn an_estimate_in_a_wrong_basin_is_not_explained() {
    let model = Duffing::new();
    let truth = [2.0, 0.06, 0.8];
    let measured = record(&model, &truth, 0);
    let fit = Refinement::new(OutputError::new(&model).unwrap());
    let wrong = fit.descend(&measured, vec![5.8, 0.1, 0.2]).unwrap().theta;
    assert!((wrong[0] - truth[0]).abs() > 0.3, "{wrong:?}");
    let plan = CheckPlan::new(99, 1, 3);
    let local = CheckPlan {
        prior_starts: 0,
        ..plan
    };
    // What the check said before: the best fit beside the estimate is the
    // estimate, so the poor fit counted as explained.
    let before = check_with(&model, &measured, &wrong, local).unwrap();
    assert!(before.fit_percent[0] < 50.0, "{:?}", before.fit_percent);
    assert!(before.explained() && before.loss_ratio < 1.01);
    let after = check_with(&model, &measured, &wrong, plan).unwrap();
    assert!(!after.explained(), "{after:?}");
    assert!(after.loss_ratio > 100.0 && after.best_fit_percent[0] > 95.0);
    assert!((after.best_theta[0] - truth[0]).abs() < 0.05);
    assert!(after.optima >= 2 && after.runner_up_ratio.is_some_and(|r| r > 100.0));
    // At the search's best fit the same record is explained.
    let right = check_with(&model, &measured, &after.best_theta, plan).unwrap();
    assert!(right.explained() && right.model_consistent());
}

/// Over many plants, estimates at the bottom of whichever basin a descent
/// from a random draw of the prior reaches (a weak estimator's worst case):
/// the local check explains every one of them in a wrong basin; the check
/// that searches the prior explains none. `PLANTS=N` runs N plants
/// instead of 12, for a larger measurement.
#[test]
fn no_wrong_basin_is_explained_over_many_plants() {
    let model = Duffing::new();
    let prior = model.spec().prior();
    let fit = Refinement::new(OutputError::new(&model).unwrap());
    let plan = CheckPlan::new(99, 1, 3);
    let (mut wrong, mut before, mut after, mut right_refused) = (0, 0, 0, 0);
    let plants: usize = std::env::var("PLANTS").map_or(12, |v| v.parse().unwrap());
    for plant in 0..plants {
        let design = prior.design(plants + 4 * plants, 5).unwrap();
        let mut truth = vec![0.0; 3];
        design.fill_theta(plant, &mut truth).unwrap();
        let measured = record(&model, &truth, plant as u64);
        let truth_basin = fit.descend(&measured, truth.clone()).unwrap();
        for draw in 0..4 {
            let mut start = vec![0.0; 3];
            design
                .fill_theta(plants + 4 * plant + draw, &mut start)
                .unwrap();
            let estimate = fit.descend(&measured, start).unwrap();
            let in_wrong_basin = estimate.loss > 2.0 * truth_basin.loss;
            let local = check_with(
                &model,
                &measured,
                &estimate.theta,
                CheckPlan {
                    prior_starts: 0,
                    ..plan
                },
            )
            .unwrap();
            let searched = check_with(&model, &measured, &estimate.theta, plan).unwrap();
            if in_wrong_basin {
                wrong += 1;
                before += usize::from(local.explained());
                after += usize::from(searched.explained());
            } else {
                right_refused += usize::from(!searched.explained());
            }
        }
    }
    println!(
        "{wrong} of {} estimates in a wrong basin: explained {before} before, {after} after; \
         {right_refused} in the truth's basin not explained",
        4 * plants
    );
    assert!(wrong >= 5, "{wrong} estimates in a wrong basin");
    assert_eq!(before, wrong);
    assert_eq!(after, 0);
    assert_eq!(right_refused, 0);
}
