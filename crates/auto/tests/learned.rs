//! Where the records' inputs differ in kind, round 3 tries the winner's
//! stage 1 with a summary network after it; a learned winner ships
//! trained.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use twostage::compress::{Arx, CompressorConfig};
use twostage::fit::MlpParams;
use twostage::models::{Conditions, ExperimentRng, IoData, ModelSpec, Prior, SimError, Simulator};
use twostage::{AutoDesign, Budget, RegressorConfig};

/// A first-order lag behind an actuator that saturates at theta[0]: a
/// record of small steps says little of the limit, a record of large
/// oscillations much, and the ARX coefficients of each say it differently.
struct SaturatingLag {
    spec: ModelSpec,
}

impl Simulator for SaturatingLag {
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
        let level = rng.random_range(0.2..2.0);
        let square = rng.random_bool(0.5);
        let (mut x, limit) = (0.0, theta[0]);
        for k in 0..n {
            let u = match square {
                true if (k / 10) % 2 == 0 => level,
                true => -level,
                false => level * (k as f64 * 0.08).sin(),
            };
            out.input_mut(0)[k] = u;
            x = 0.8 * x + 0.2 * limit * (u / limit).tanh();
            let e: f64 = StandardNormal.sample(rng);
            out.output_mut(0)[k] = x + 0.02 * e;
        }
        Ok(())
    }
}

fn model() -> SaturatingLag {
    let prior = Prior::uniform_box(&[0.3], &[1.5]).unwrap();
    SaturatingLag {
        spec: ModelSpec::new("saturating-lag", &["limit"], prior, 1.0, 120)
            .unwrap()
            .with_signals(&["u"], &["y"]),
    }
}

#[test]
fn inputs_of_mixed_kinds_earn_a_learned_rival() {
    let model = model();
    let net = RegressorConfig::Mlp(MlpParams::new(&[6]).unwrap().check().unwrap());
    let outcome = AutoDesign::new(&model)
        .budget(Budget::Simulations(800))
        .compressors(vec![Arx::new(2, 2).unwrap().into()])
        .networks(net, Vec::new())
        .settings(|b| b.seed(3).calibration(100).validation(100))
        .run()
        .unwrap();
    let learned: Vec<_> = outcome
        .candidates
        .iter()
        .filter(|c| c.compressor.contains("learned"))
        .collect();
    assert_eq!(learned.len(), 1, "{:?}", outcome.candidates);
    let rival = learned[0];
    assert_eq!(rival.round, 3);
    assert!(rival.status.is_scored(), "{:?}", rival.status);
    assert!(
        rival.design.starts_with("arx:2,2+summary+learned:8,8,8"),
        "the levels differ: the summary comes before the network ({})",
        rival.design
    );
    // The network reads what the coefficients alone do not.
    let coefficients = outcome.candidates.iter().find(|c| c.round == 1).unwrap();
    assert!(
        rival.score < 0.9 * coefficients.score,
        "learned {} against {}",
        rival.score,
        coefficients.score
    );
}

/// A learned stage 1 asked for in round 1 is trained there, and ships
/// with its network trained.
#[test]
fn a_learned_winner_ships_trained() {
    let model = model();
    let learned: CompressorConfig = "arx:2,2+learned:4,4".parse().unwrap();
    let net = RegressorConfig::Mlp(MlpParams::new(&[6]).unwrap().check().unwrap());
    let outcome = AutoDesign::new(&model)
        .budget(Budget::Simulations(400))
        .compressors(vec![learned])
        .networks(net, Vec::new())
        .settings(|b| b.seed(4).calibration(100).validation(100))
        .run()
        .unwrap();
    let best = &outcome.candidates[outcome.best];
    assert!(best.compressor.contains("learned"), "{best:?}");
    assert!(
        outcome
            .candidates
            .iter()
            .filter(|c| c.compressor.contains("learned"))
            .all(|c| c.status.is_scored()),
        "{:#?}",
        outcome.candidates
    );
    let stage1 = outcome.estimator.compressor();
    assert!(
        matches!(stage1, CompressorConfig::Learned(l) if l.network().is_some()),
        "{stage1}"
    );
    assert!(stage1.untrained_summary().is_none());
    let mut record = IoData::zeros(0, 0, 0);
    let mut rng = twostage::models::experiment_rng(17, 0);
    model.simulate(&[0.9], &mut rng, &mut record).unwrap();
    let theta = outcome.estimator.estimate_record(&record).unwrap();
    assert!((theta[0] - 0.9).abs() < 0.3, "{theta:?}");
}
