//! Round 1's rows under a time budget: where the source
//! simulates, round 1 screens quickly on half the screening rows and
//! round 2 goes back to all of them where round 1 proved cheap; rows the
//! user sets are fitted as set.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use twostage::compress::Arx;
use twostage::fit::MlpParams;
use twostage::models::Benchmark;
use twostage::{AutoDesign, AutoOutcome, Budget, RegressorConfig};

fn search(model: &Benchmark, screening_rows: Option<usize>) -> AutoOutcome {
    let net = |h: usize| {
        RegressorConfig::Mlp(
            MlpParams::new(&[h])
                .unwrap()
                .restarts(1)
                .max_iterations(30)
                .check()
                .unwrap(),
        )
    };
    let design = AutoDesign::new(model)
        .budget(Budget::Seconds(4.0))
        .compressors(vec![
            Arx::new(2, 2).unwrap().into(),
            Arx::new(3, 3).unwrap().into(),
        ])
        .networks(net(3), vec![net(2)])
        .settings(|b| b.seed(3).calibration(100).validation(100));
    match screening_rows {
        Some(rows) => design.screening_rows(rows),
        None => design,
    }
    .run()
    .unwrap()
}

/// The rows every candidate of `round` was fitted on, which must agree.
fn rows_of(outcome: &AutoOutcome, round: usize) -> usize {
    let rows: Vec<usize> = outcome
        .candidates
        .iter()
        .filter(|c| c.round == round && c.status.is_scored())
        .map(|c| c.fit_rows)
        .collect();
    assert!(
        !rows.is_empty(),
        "no scored round-{round} candidate:\n{outcome}"
    );
    assert!(rows.iter().all(|&r| r == rows[0]), "{rows:?}:\n{outcome}");
    rows[0]
}

#[test]
fn a_simulated_search_screens_on_half_the_rows_then_fits_them_all() {
    let model = Benchmark::builder().n_samples(100).build().unwrap();
    let quick = search(&model, None);
    let (first, second) = (rows_of(&quick, 1), rows_of(&quick, 2));
    // Round 1's tiny networks take milliseconds of a 4 s budget: round 2
    // goes back to the full screening rows (the chart's fitting rows
    // here, under 4000), twice round 1's within rounding.
    assert!(first < second, "{first} against {second}:\n{quick}");
    assert!(2 * first <= second && second <= 2 * first + 1, "{quick}");
    // Rows set by the user are fitted as set, whatever the source.
    let set = first / 2;
    let asked = search(&model, Some(set));
    assert_eq!(rows_of(&asked, 1), set, "{asked}");
    assert!(rows_of(&asked, 2) >= second, "{asked}");
}
