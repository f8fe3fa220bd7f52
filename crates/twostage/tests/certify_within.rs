//! A training's validation grown until the certificate a user reads is
//! within a multiple of the error seen: its records are a fixed run's,
//! bit for bit; it stops at its maximum, and a chart that cannot grow
//! says what it would take.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::Mutex;

use common::write_chart;
use twostage::models::{Benchmark, Simulator};
use twostage::sources::ChartFiles;
use twostage::{Estimator, Progress, RecordSource, RunSettings, TwoStage};

/// Every note a run makes.
#[derive(Default)]
struct Notes(Mutex<Vec<String>>);

impl Progress for Notes {
    fn note(&self, message: &str) {
        self.0.lock().unwrap().push(message.to_string());
    }
}

impl Notes {
    fn about_the_certificate(&self) -> String {
        let notes = self.0.lock().unwrap();
        let found: Vec<&String> = notes
            .iter()
            .filter(|n| n.contains("certificate") || n.contains("certified"))
            .collect();
        assert_eq!(found.len(), 1, "{notes:?}");
        found[0].clone()
    }
}

fn model() -> Benchmark {
    Benchmark::builder().n_samples(200).build().unwrap()
}

/// A small estimator of `model`, its validation as `settings` say.
fn trained(model: &Benchmark, settings: RunSettings, notes: &Notes) -> Estimator {
    TwoStage::builder(model)
        .preset(twostage::paper_benchmark())
        .simulations(400)
        .settings(RunSettings {
            calibration: 200,
            seed: Some(4),
            ..settings
        })
        .progress(notes)
        .train()
        .unwrap()
}

#[test]
fn a_grown_validation_meets_its_multiple_on_the_records_a_fixed_run_of_its_size_reads() {
    let model = model();
    let notes = Notes::default();
    let grown = trained(
        &model,
        RunSettings {
            validation: 300,
            certify_within: Some(1.5),
            ..RunSettings::default()
        },
        &notes,
    );
    let report = grown.validation().unwrap();
    let r = report.total.r as usize;
    assert!(r > 300, "r = {r}");
    assert!(report.certified_ratio() <= 1.5, "{report}");
    let said = notes.about_the_certificate();
    assert!(
        said.contains(&format!("grown to r = {r} records (rounds of 300, ")),
        "{said}"
    );
    // The records past the first round are those a run of r fixed
    // records validates on: the same report, bit for bit.
    let fixed = trained(
        &model,
        RunSettings {
            validation: r,
            certify_within: None,
            ..RunSettings::default()
        },
        &Notes::default(),
    );
    assert_eq!(fixed.validation(), Some(report));
    // And the first round alone fell short of the multiple.
    let first = trained(
        &model,
        RunSettings {
            validation: 300,
            certify_within: None,
            ..RunSettings::default()
        },
        &Notes::default(),
    );
    assert!(first.validation().unwrap().certified_ratio() > 1.5);
}

#[test]
fn a_validation_that_reaches_its_most_records_says_what_it_would_take() {
    let model = model();
    let notes = Notes::default();
    let short = trained(
        &model,
        RunSettings {
            validation: 300,
            certify_within: Some(1.05),
            max_validation: 700,
            ..RunSettings::default()
        },
        &notes,
    );
    let report = short.validation().unwrap();
    assert_eq!(report.total.r, 700);
    let said = notes.about_the_certificate();
    let wanted: u64 = said
        .split("about ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .unwrap_or_else(|| panic!("{said}"))
        .parse()
        .unwrap();
    assert_eq!(Some(wanted), report.records_for_ratio(1.05), "{said}");
    assert!(wanted > 700 && said.contains("the most allowed"), "{said}");
}

#[test]
fn a_chart_s_validation_cannot_grow_and_says_how_many_records_it_would_take() {
    let model = model();
    let dir = std::env::temp_dir().join(format!("twostage-certify-chart-{}", std::process::id()));
    write_chart(&model, &dir, 700, 3);
    let chart = ChartFiles::open(&dir, model.spec()).unwrap();
    let notes = Notes::default();
    let estimator = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .settings(RunSettings {
            validation: 200,
            calibration: 100,
            ..RunSettings::default()
        })
        .records(RecordSource::Files {
            training: &chart,
            calibration: None,
            validation: None,
        })
        .progress(&notes)
        .train()
        .unwrap();
    let report = estimator.validation().unwrap();
    assert_eq!(report.total.r, 200);
    let said = notes.about_the_certificate();
    assert!(said.contains("cannot grow"), "{said}");
    assert!(
        said.contains(&format!("{:.3} times", report.certified_ratio())),
        "{said}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_deadline_passed_ends_the_growth_at_the_first_round_and_says_so() {
    let model = model();
    let notes = Notes::default();
    let run = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .simulations(400)
        .settings(RunSettings {
            calibration: 200,
            validation: 300,
            certify_within: Some(1.05),
            seed: Some(4),
            ..RunSettings::default()
        })
        .progress(&notes)
        .prepare()
        .unwrap()
        .with_deadline(Some(std::time::Instant::now()));
    let estimator = run.fit().unwrap();
    assert_eq!(estimator.validation().unwrap().total.r, 300);
    let said = notes.about_the_certificate();
    assert!(
        said.contains("as many as the time budget afforded"),
        "{said}"
    );
}
