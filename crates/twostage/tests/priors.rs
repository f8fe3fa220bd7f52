//! Priors other than the uniform box (the paper's Section 4.1 allows them):
//! a log-normal gain over three decades and a truncated-normal pole.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use rand_distr::{Distribution, StandardNormal};
use twostage::TwoStage;
use twostage::compress::Arx;
use twostage::models::{
    Conditions, ExperimentRng, IoData, Marginal, ModelSpec, Prior, SimError, Simulator,
    experiment_rng,
};

/// `y_k = a y_{k-1} + K u_{k-1} + e_k`, white unit input, noise sd 0.05.
struct FirstOrder {
    spec: ModelSpec,
}

impl FirstOrder {
    fn new() -> Self {
        let prior = Prior::new(vec![
            Marginal::LogNormal {
                mu: 0.0,
                sigma: 1.0,
            },
            Marginal::TruncatedNormal {
                mu: 0.5,
                sigma: 0.2,
                low: 0.0,
                high: 0.9,
            },
        ])
        .unwrap();
        Self {
            spec: ModelSpec::new("first-order", &["K", "a"], prior, 1.0, 200).unwrap(),
        }
    }
}

impl Simulator for FirstOrder {
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
        let (gain, pole) = (theta[0], theta[1]);
        let n = self.spec.n_samples();
        out.resize(n, 1, 1);
        let (u, y) = out.siso_mut();
        for v in u.iter_mut() {
            *v = StandardNormal.sample(rng);
        }
        let mut previous = 0.0;
        for k in 0..n {
            let drive = if k > 0 { gain * u[k - 1] } else { 0.0 };
            previous = pole * previous + drive;
            let e: f64 = StandardNormal.sample(rng);
            y[k] = previous + 0.05 * e;
        }
        Ok(())
    }
}

#[test]
fn a_log_normal_gain_is_learned_in_logs_and_estimated_within_its_support() {
    let model = FirstOrder::new();
    let estimator = TwoStage::builder(&model)
        .compressor(Arx::new(1, 1).unwrap())
        .simulations(1500)
        .validation(300)
        .calibration(0)
        .seed(5)
        .train()
        .unwrap();
    // The file keeps the priors, so a loaded estimator maps back the same way.
    assert_eq!(estimator.marginals(), model.prior().marginals());
    let loaded = twostage::Estimator::from_bytes(&estimator.to_bytes().unwrap()).unwrap();
    assert_eq!(loaded, estimator);
    // Across three decades of gain the relative error stays small, which a
    // network fitted to K itself (errors in absolute units) does not manage
    // for the small gains; and every estimate is a positive gain in the box.
    let mut worst = 0.0f64;
    for (i, gain) in [0.02, 0.1, 1.0, 8.0, 40.0].into_iter().enumerate() {
        let mut record = model.spec().new_record();
        model
            .simulate(&[gain, 0.6], &mut experiment_rng(77, i as u64), &mut record)
            .unwrap();
        let theta = loaded.estimate_record(&record).unwrap();
        assert!(
            theta[0] > 0.0 && model.prior().contains(&theta),
            "{theta:?}"
        );
        worst = worst.max((theta[0] / gain - 1.0).abs());
    }
    // Measured: 0.076 in logs, 0.28 with K learned as it is.
    assert!(worst < 0.15, "worst relative error of K: {worst}");
    let report = estimator.validation().unwrap();
    // The certificate is stated on the prior's box: for the log-normal gain
    // its central 1 - 2e-6.
    let (low, high) = model.prior().marginals()[0].range();
    assert_eq!((estimator.lower()[0], estimator.upper()[0]), (low, high));
    assert!(report.parameters[1].rmse < 0.05, "{report}");
}
