//! The estimator's posterior draws against the benchmark's exact
//! posterior (its Kalman likelihood on a refined grid), their coverage of
//! the parameters that made the records, and the estimator file that
//! carries them.
#![allow(clippy::unwrap_used)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use twostage::baselines::BayesBenchmark;
use twostage::fit::{MixtureDensity, MlpParams};
use twostage::models::{Benchmark, Simulator, experiment_rng};
use twostage::{EstimateRequest, EstimateWith, Estimator, Purpose, RefineWhich, TwoStage};

fn trained(model: &Benchmark) -> Estimator {
    TwoStage::builder(model)
        .preset(twostage::paper_benchmark())
        .simulations(4000)
        .validation(0)
        .calibration(0)
        .seed(7)
        .posterior(MixtureDensity::new(MlpParams::new(&[24]).unwrap().check().unwrap(), 3).unwrap())
        .train()
        .unwrap()
}

/// On fresh records the draws are calibrated: their central 90% holds the
/// true parameter about 90% of the time, and their mean misses it by what
/// their spread says (the mean squared miss is the mean variance, as for
/// any posterior given what stage 1 keeps). They are never narrower than
/// the exact posterior given the whole record: stage 1's features hold
/// no more than the record.
#[test]
fn the_draws_are_calibrated_and_no_surer_than_the_exact_posterior() {
    let model = Benchmark::builder().n_samples(400).build().unwrap();
    let estimator = trained(&model);
    let bayes = BayesBenchmark::default()
        .initial_points(361)
        .tolerance(1e-5);
    let (records, draws) = (300, 2000);
    let design = model.spec().prior().design(records, 31).unwrap();
    let (mut miss, mut spread, mut covered) = (0.0, 0.0, 0);
    let (mut drawn_variance, mut exact_variance) = (0.0, 0.0);
    for k in 0..records {
        let mut rng = experiment_rng(31, k as u64);
        let mut theta = [0.0];
        design.fill_theta(k, &mut theta).unwrap();
        let mut record = model.spec().new_record();
        model.simulate(&theta, &mut rng, &mut record).unwrap();
        let mut out = vec![0.0; draws];
        estimator
            .sample_record(&record, &mut ChaCha8Rng::seed_from_u64(k as u64), &mut out)
            .unwrap();
        assert!(out.iter().all(|v| (-0.9..=0.9).contains(v)));
        let mean = out.iter().sum::<f64>() / draws as f64;
        let variance = out.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / draws as f64;
        miss += (mean - theta[0]).powi(2);
        spread += variance;
        out.sort_by(f64::total_cmp);
        let (low, high) = (out[draws / 20], out[draws - draws / 20 - 1]);
        covered += usize::from((low..=high).contains(&theta[0]));
        if k < 40 {
            let exact = bayes.posterior(&record).unwrap();
            drawn_variance += variance;
            exact_variance += exact.sd * exact.sd;
        }
    }
    let coverage = covered as f64 / records as f64;
    let calibration = miss / spread;
    assert!((0.85..=0.95).contains(&coverage), "coverage {coverage}");
    assert!(
        (0.8..1.25).contains(&calibration),
        "miss / spread {calibration}"
    );
    assert!(
        drawn_variance > 0.9 * exact_variance,
        "draws' variance {drawn_variance}, exact {exact_variance}"
    );
}

/// An estimator with a posterior is written as format version 9 (10 is
/// for parameters held at values) and read back whole; one without keeps
/// its older version; a draw asked of it is refused with what to do.
#[test]
fn the_posterior_travels_in_the_estimator_file() {
    let model = Benchmark::builder().n_samples(200).build().unwrap();
    let with = TwoStage::builder(&model)
        .simulations(300)
        .validation(0)
        .calibration(0)
        .posterior(MixtureDensity::new(MlpParams::new(&[4]).unwrap().check().unwrap(), 1).unwrap())
        .train()
        .unwrap();
    let bytes = with.to_bytes().unwrap();
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 9);
    let read = Estimator::from_bytes(&bytes).unwrap();
    assert_eq!(read, with);
    assert!(read.posterior().is_some());
    // Draws are the two-stage posterior's: asked beside a refinement or a
    // joint fit, whose estimates are not, they are refused by the request.
    for (refine, joint) in [(Some(RefineWhich::All), false), (None, true)] {
        let refused = EstimateRequest::new(EstimateWith::Estimator(Box::new(read.clone())))
            .samples(Some(10))
            .refine(refine)
            .joint(joint)
            .prepare()
            .err()
            .unwrap();
        assert_eq!(refused.purpose, Purpose::Samples);
        assert!(
            refused.to_string().contains("refined or joint"),
            "{refused}"
        );
    }
    let without = TwoStage::builder(&model)
        .simulations(300)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap();
    let bytes = without.to_bytes().unwrap();
    assert!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()) < 9);
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.1], &mut experiment_rng(1, 0), &mut record)
        .unwrap();
    let refused = without
        .sample_record(&record, &mut ChaCha8Rng::seed_from_u64(0), &mut [0.0; 4])
        .unwrap_err()
        .to_string();
    assert!(refused.contains("--posterior"), "{refused}");
}

/// A validation run scores the posterior on its own fresh records: 90%
/// regions and intervals hold the truth about 90% of the time and the
/// ranks are near uniform, as the draws' coverage above; an estimator
/// without a posterior gets no score.
#[test]
fn a_validation_run_scores_the_posterior() {
    let model = Benchmark::builder().n_samples(400).build().unwrap();
    let estimator = trained(&model);
    let plan = twostage::ValidationPlan {
        sims: Some(600),
        ..twostage::ValidationPlan::default()
    };
    let run = twostage::validate_estimator(&estimator, &model, &plan, &twostage::Silent).unwrap();
    let posterior = run.posterior.clone().unwrap();
    assert_eq!(
        (posterior.records, posterior.draws),
        (600, twostage::CALIBRATION_DRAWS)
    );
    assert!((0.85..=0.95).contains(&posterior.joint[1]), "{posterior:?}");
    assert!(
        (0.85..=0.95).contains(&posterior.central[0][1]),
        "{posterior:?}"
    );
    assert!(posterior.uniformity_p[0] > 1e-3, "{posterior:?}");
    assert_eq!(
        run.report_json().unwrap()["posterior"]["records"],
        serde_json::json!(600)
    );
    let plain = TwoStage::builder(&model)
        .preset(twostage::paper_benchmark())
        .simulations(600)
        .validation(0)
        .calibration(0)
        .train()
        .unwrap();
    let run = twostage::validate_estimator(&plain, &model, &plan, &twostage::Silent).unwrap();
    assert!(run.posterior.is_none());
    assert!(run.report_json().unwrap().get("posterior").is_none());
}
