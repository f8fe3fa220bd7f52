//! A candidate the model cannot take is named, not dropped in silence.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rand_distr::{Distribution, StandardNormal};
use twostage::compress::{Arx, Narx};
use twostage::fit::MlpParams;
use twostage::models::{Conditions, ExperimentRng, IoData, ModelSpec, Prior, SimError, Simulator};
use twostage::{AutoDesign, Budget, RegressorConfig};

mod common;
use common::Notes;

/// A first-order system seen by two noisy sensors: one input, two
/// outputs, which a NARX (one input, one output) cannot take.
struct TwoSensors {
    spec: ModelSpec,
}

impl Simulator for TwoSensors {
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
        let n = self.spec.n_samples();
        out.resize(n, 1, 2);
        let mut state = vec![0.0; n];
        for k in 0..n {
            let u: f64 = StandardNormal.sample(rng);
            out.input_mut(0)[k] = u;
            state[k] = theta[0] * if k > 0 { state[k - 1] } else { 0.0 } + u;
        }
        for j in 0..2 {
            for (y, x) in out.output_mut(j).iter_mut().zip(&state) {
                let e: f64 = StandardNormal.sample(rng);
                *y = x + 0.1 * e;
            }
        }
        Ok(())
    }
}

#[test]
fn a_compressor_the_model_cannot_take_is_named_and_left_out() {
    let prior = Prior::uniform_box(&[0.1], &[0.8]).unwrap();
    let model = TwoSensors {
        spec: ModelSpec::new("two-sensors", &["a"], prior, 1.0, 100)
            .unwrap()
            .with_signals(&["u"], &["y1", "y2"]),
    };
    let net = RegressorConfig::Mlp(MlpParams::new(&[3]).unwrap().check().unwrap());
    let notes = Notes::default();
    let outcome = AutoDesign::new(&model)
        .budget(Budget::Simulations(200))
        .compressors(vec![
            Arx::new(1, 1).unwrap().into(),
            Narx::new(1, 1, 2).unwrap().into(),
        ])
        .networks(net, Vec::new())
        .settings(|b| b.calibration(0).validation(0).progress(&notes))
        .run()
        .unwrap();
    let notes = notes.0.lock().unwrap();
    let named: Vec<&String> = notes.iter().filter(|n| n.contains("left out")).collect();
    assert_eq!(named.len(), 1, "{notes:?}");
    assert!(named[0].contains("NARX"), "{named:?}");
    assert!(
        outcome
            .candidates
            .iter()
            .all(|c| !c.compressor.contains("NARX")),
        "{:?}",
        outcome.candidates
    );
}

/// A first-order system whose input is now and then never applied: an
/// ARX cannot take such a record, but it can take the others.
struct SometimesIdle {
    spec: ModelSpec,
}

impl Simulator for SometimesIdle {
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
        let n = self.spec.n_samples();
        out.resize(n, 1, 1);
        let idle = rand::RngExt::random_bool(rng, 0.004);
        let mut x = 0.0;
        for k in 0..n {
            let u: f64 = if idle {
                0.0
            } else {
                StandardNormal.sample(rng)
            };
            out.input_mut(0)[k] = u;
            x = theta[0] * x + u;
            let e: f64 = StandardNormal.sample(rng);
            out.output_mut(0)[k] = x + 0.1 * e;
        }
        Ok(())
    }
}

/// A few records a structure cannot compress leave the search, counted
/// as failures; the structure stays a candidate.
#[test]
fn a_record_the_stage_one_cannot_take_is_left_out_not_the_stage_one() {
    let prior = Prior::uniform_box(&[0.1], &[0.8]).unwrap();
    let model = SometimesIdle {
        spec: ModelSpec::new("sometimes-idle", &["a"], prior, 1.0, 100)
            .unwrap()
            .with_signals(&["u"], &["y"]),
    };
    let net = RegressorConfig::Mlp(MlpParams::new(&[3]).unwrap().check().unwrap());
    let outcome = AutoDesign::new(&model)
        .budget(Budget::Simulations(1000))
        .compressors(vec![Arx::new(1, 1).unwrap().into()])
        .networks(net, Vec::new())
        .settings(|b| b.seed(2).calibration(0).validation(0))
        .run()
        .unwrap();
    let first = &outcome.candidates[0];
    assert!(first.status.is_scored(), "{:?}", first.status);
    // Far inside the prior's spread (0.2).
    assert!(first.rmse[0] < 0.1, "{:?}", first.rmse);
    assert!(
        (1..=10).contains(&outcome.failures),
        "idle records left out: {}",
        outcome.failures
    );
}
