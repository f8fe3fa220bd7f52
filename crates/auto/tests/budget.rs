//! A time budget that cannot afford the calibration and validation records
//! asked for shrinks them, with a note, instead of refusing the run.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use rand_distr::{Distribution, StandardNormal};
use twostage::compress::Arx;
use twostage::fit::MlpParams;
use twostage::models::{Conditions, ExperimentRng, IoData, ModelSpec, Prior, SimError, Simulator};
use twostage::{AutoDesign, Budget, RegressorConfig};

mod common;
use common::Notes;

/// A first-order system that takes 2 ms a record, as a slow simulator
/// would: the budget's pilot measures it.
struct SlowFirstOrder {
    spec: ModelSpec,
}

impl Simulator for SlowFirstOrder {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        _: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        std::thread::sleep(Duration::from_millis(2));
        let n = self.spec.n_samples();
        out.resize(n, 1, 1);
        let mut y = 0.0;
        for k in 0..n {
            let u: f64 = StandardNormal.sample(rng);
            let e: f64 = StandardNormal.sample(rng);
            out.input_mut(0)[k] = u;
            y = theta[0] * y + u;
            out.output_mut(0)[k] = y + 0.1 * e;
        }
        Ok(())
    }
}

#[test]
fn a_budget_shrinks_calibration_and_validation_rather_than_refusing() {
    let prior = Prior::uniform_box(&[0.1], &[0.8]).unwrap();
    let model = SlowFirstOrder {
        spec: ModelSpec::new("slow", &["a"], prior, 1.0, 60)
            .unwrap()
            .with_signals(&["u"], &["y"]),
    };
    let net = RegressorConfig::Mlp(MlpParams::new(&[3]).unwrap().check().unwrap());
    let notes = Notes::default();
    // 4000 held-out records take at least 4000 x 2 ms / cores: more than
    // half of an 8 s budget on any machine of up to 2 cores, and 200 fit.
    let asked = 2000;
    let outcome = AutoDesign::new(&model)
        .budget(Budget::Seconds(8.0))
        .compressors(vec![Arx::new(1, 1).unwrap().into()])
        .networks(net, Vec::new())
        .settings(|b| b.calibration(asked).validation(asked).progress(&notes))
        .run()
        .unwrap();
    let notes = notes.0.lock().unwrap();
    let said: Vec<&String> = notes
        .iter()
        .filter(|n| n.contains("the budget affords"))
        .collect();
    assert_eq!(said.len(), 1, "{notes:?}");
    let validated = outcome.estimator.validation().map(|v| v.total.r).unwrap();
    assert!(
        (100..asked as u64).contains(&validated),
        "{validated} validation records: {said:?}"
    );
    assert!(
        said[0].contains(&format!("{validated} validation records")),
        "{said:?}"
    );
}
