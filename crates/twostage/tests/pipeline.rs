//! The trained estimator as a user sees it: training, estimates, files.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use twostage::InvalidSetting;

use twostage::compress::Arx;
use twostage::estimator::Error as EstimatorError;
use twostage::fit::MlpParams;
use twostage::models::{
    Benchmark, Conditions, ExperimentRng, IoData, ModelSpec, SimError, Simulator, experiment_rng,
};
use twostage::{AutoDesign, Error, Estimator, FileError, RegressorConfig, TwoStage};

fn small_benchmark() -> Benchmark {
    Benchmark::builder().n_samples(400).build().unwrap()
}

fn small_estimator(model: &Benchmark, seed: u64) -> Estimator {
    TwoStage::builder(model)
        .compressor(Arx::new(3, 3).unwrap())
        .regressor(RegressorConfig::Mlp(
            MlpParams::new(&[6]).unwrap().restarts(2).check().unwrap(),
        ))
        .simulations(300)
        .calibration(100)
        .validation(100)
        .seed(seed)
        .train()
        .unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_saved_estimator_loads_back_identical_and_estimates_the_same() {
    let model = small_benchmark();
    let estimator = small_estimator(&model, 3);
    let path = scratch("roundtrip").join("bench.tsest");
    estimator.save(&path).unwrap();
    let loaded = Estimator::load(&path).unwrap();
    assert_eq!(loaded, estimator);
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.2], &mut experiment_rng(5, 5), &mut record)
        .unwrap();
    let a = estimator.estimate_record(&record).unwrap();
    let b = loaded.estimate_record(&record).unwrap();
    assert_eq!(a[0].to_bits(), b[0].to_bits());
    let json: serde_json::Value = serde_json::from_str(&estimator.to_json().unwrap()).unwrap();
    assert_eq!(json["param_names"][0], "theta");
    assert_eq!(json["training"]["simulations"], 300);
}

#[test]
fn damaged_files_get_a_clear_error_each() {
    let model = small_benchmark();
    let bytes = small_estimator(&model, 4).to_bytes().unwrap();
    let kind = |bytes: &[u8]| match Estimator::from_bytes(bytes) {
        Err(EstimatorError::File { path: None, error }) => error,
        other => panic!("expected a file error, got {other:?}"),
    };
    let header = bytes.len() as u64 - 24;
    // Truncated, in the payload and in the header.
    assert_eq!(
        kind(&bytes[..bytes.len() - 10]),
        FileError::Truncated {
            part: "payload",
            expected: header,
            found: header - 10
        }
    );
    assert!(matches!(
        kind(&bytes[..15]),
        FileError::Truncated {
            part: "header",
            expected: 24,
            found: 15
        }
    ));
    // Corrupted: one payload bit flipped.
    let mut flipped = bytes.clone();
    let last = flipped.len() - 3;
    flipped[last] ^= 0x10;
    assert!(matches!(kind(&flipped), FileError::BadChecksum { .. }));
    // Foreign: a PNG header, and an empty file; the message says what to do.
    assert_eq!(
        kind(b"\x89PNG\r\n\x1a\n0000000000000000000000"),
        FileError::BadMagic
    );
    assert_eq!(kind(b""), FileError::BadMagic);
    assert!(FileError::BadMagic.to_string().contains("twostage train"));
    // Without a path the message still says what it is about; with one, it
    // names the file.
    let bare = Estimator::from_bytes(b"").unwrap_err().to_string();
    assert!(bare.starts_with("estimator file: not a twostage"), "{bare}");
    // Newer and impossible format versions.
    let mut newer = bytes.clone();
    let next = twostage::FORMAT_VERSION + 1;
    newer[8..12].copy_from_slice(&next.to_le_bytes());
    assert_eq!(
        kind(&newer),
        FileError::NewerVersion {
            found: next,
            supported: twostage::FORMAT_VERSION
        }
    );
    assert!(kind(&newer).to_string().contains("upgrade twostage"));
    newer[8..12].copy_from_slice(&0u32.to_le_bytes());
    assert_eq!(kind(&newer), FileError::UnknownVersion { found: 0 });
    // Trailing bytes.
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(kind(&longer), FileError::TrailingBytes { extra: 1 });
    // A missing file names itself.
    let err = Estimator::load("/nonexistent/x.tsest").unwrap_err();
    assert!(err.to_string().contains("/nonexistent/x.tsest"), "{err}");
}

#[test]
fn training_gives_the_same_file_with_one_and_two_threads() {
    let model = small_benchmark();
    let train = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| small_estimator(&model, 11).to_bytes().unwrap())
    };
    assert_eq!(train(1), train(2));
}

#[test]
fn conformal_intervals_cover_fresh_simulations_at_their_level() {
    // Linear stage 2 keeps this quick; coverage holds for any estimator.
    let model = small_benchmark();
    let mut covered = 0.0;
    let seeds = [1u64, 2, 3, 4];
    for seed in seeds {
        let estimator = TwoStage::builder(&model)
            .simulations(300)
            .linear(1e-6)
            .unwrap()
            .calibration(400)
            .alpha(0.2)
            .validation(1500)
            .seed(seed)
            .train()
            .unwrap();
        let report = estimator.validation().unwrap();
        covered += report.parameters[0].interval_coverage.unwrap();
    }
    let mean = covered / seeds.len() as f64;
    // Expected coverage ceil(401 * 0.8) / 401 = 0.8005; the average over
    // four calibrations has a standard deviation near 0.012.
    assert!((0.765..0.84).contains(&mean), "mean coverage {mean}");
}

#[test]
fn estimates_are_clipped_to_the_prior_box() {
    let model = small_benchmark();
    let estimator = small_estimator(&model, 5);
    // A record far outside what training saw: a huge output.
    let mut record = model.spec().new_record();
    model
        .simulate(&[0.3], &mut experiment_rng(1, 1), &mut record)
        .unwrap();
    for v in record.output_mut(0) {
        *v *= 1e3;
    }
    let theta = estimator.estimate_record(&record).unwrap();
    assert!((-0.9..=0.9).contains(&theta[0]), "{theta:?}");
}

#[test]
fn bad_records_fail_alone_in_a_batch() {
    let model = small_benchmark();
    let estimator = small_estimator(&model, 6);
    let good = {
        let mut r = model.spec().new_record();
        model
            .simulate(&[0.1], &mut experiment_rng(2, 0), &mut r)
            .unwrap();
        r
    };
    let constant_input = IoData::siso(&[1.0; 400], good.output(0)).unwrap();
    let too_short = IoData::siso(&good.input(0)[..5], &good.output(0)[..5]).unwrap();
    let results = estimator.estimate_batch(&[good.clone(), constant_input, too_short, good]);
    assert!(results[0].is_ok() && results[3].is_ok());
    let e1 = results[1].as_ref().unwrap_err().to_string();
    assert!(e1.contains("u is constant"), "{e1}");
    let e2 = results[2].as_ref().unwrap_err().to_string();
    assert!(e2.contains("too short"), "{e2}");
    let e = estimator.estimate(&[1.0, 2.0], &[1.0]).unwrap_err();
    assert!(
        matches!(&e, EstimatorError::Simulation(twostage::models::SimError::InvalidData(m))
            if m.contains("u has 2 samples but y has 1")),
        "u and y of different lengths: {e}"
    );
}

/// The benchmark, failing for theta above a threshold.
struct Fragile {
    inner: Benchmark,
    above: f64,
}

impl Simulator for Fragile {
    fn spec(&self) -> &ModelSpec {
        self.inner.spec()
    }
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        _: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        if theta[0] > self.above {
            return Err(SimError::Diverged {
                theta: theta.to_vec(),
                time: 0.0,
            });
        }
        self.inner.simulate(theta, rng, out)
    }
}

#[test]
fn failed_simulations_are_dropped_and_counted_up_to_a_limit() {
    let rare = Fragile {
        inner: small_benchmark(),
        above: 0.89,
    };
    let estimator = TwoStage::builder(&rare)
        .simulations(400)
        .linear(1e-6)
        .unwrap()
        .calibration(0)
        .validation(0)
        .max_failure_fraction(0.05)
        .train()
        .unwrap();
    let failures = estimator.training().failures;
    // theta > 0.89 has probability 0.01 / 1.8 = 0.56%: a few of 400.
    assert!((1..=12).contains(&failures), "{failures} failures");
    let often = Fragile {
        inner: small_benchmark(),
        above: 0.0,
    };
    let err = TwoStage::builder(&often)
        .simulations(400)
        .linear(1e-6)
        .unwrap()
        .train()
        .unwrap_err();
    match err {
        Error::Source(twostage::sources::Error::TooManyFailures {
            stage,
            failed,
            total,
            ..
        }) => {
            assert_eq!(stage, "training");
            assert_eq!(total, 400);
            assert!(failed > 150);
        }
        other => panic!("expected too many failures, got {other}"),
    }
}

#[test]
fn invalid_builder_settings_are_refused() {
    let model = small_benchmark();
    let refused = |builder: TwoStage<'_, _>| -> (&'static str, String) {
        match builder.train() {
            Err(Error::Estimator(EstimatorError::InvalidSetting(InvalidSetting {
                name,
                value,
                ..
            }))) => (name, value),
            other => panic!("expected an invalid setting, got {other:?}"),
        }
    };
    let base = || TwoStage::builder(&model);
    assert_eq!(refused(base().simulations(5)), ("simulations", "5".into()));
    assert_eq!(refused(base().alpha(1.5)), ("alpha", "1.5".into()));
    assert_eq!(refused(base().delta(0.0)), ("delta", "0".into()));
}

#[test]
fn a_narx_estimator_gets_calibrated_scales_and_learns() {
    use twostage::CompressorConfig;
    use twostage::compress::Narx;
    let model = small_benchmark();
    let estimator = TwoStage::builder(&model)
        .compressor(Narx::new(2, 2, 2).unwrap())
        .simulations(400)
        .linear(1e-6)
        .unwrap()
        .calibration(0)
        .validation(300)
        .seed(2)
        .train()
        .unwrap();
    let CompressorConfig::Narx(narx) = estimator.compressor() else {
        panic!("expected a NARX compressor");
    };
    let (u, y) = narx.scales();
    // u ~ N(0, 1): RMS near 1; y's RMS is set by the system, well above 1.
    assert!((u[0] - 1.0).abs() < 0.1, "input scale {}", u[0]);
    assert!(y[0] > 1.2, "output scale {}", y[0]);
    // Even a linear map of NARX features learns theta (the prior's spread is 0.52).
    let rmse = estimator.validation().unwrap().parameters[0].rmse;
    assert!(rmse < 0.3, "RMSE {rmse}");
}

#[test]
fn intervals_are_kept_without_validation() {
    let model = small_benchmark();
    let estimator = TwoStage::builder(&model)
        .simulations(200)
        .linear(1e-6)
        .unwrap()
        .calibration(100)
        .validation(0)
        .train()
        .unwrap();
    assert!(estimator.validation().is_none());
    let widths = estimator
        .intervals()
        .expect("calibrated intervals")
        .half_widths();
    assert!(widths[0] > 0.0 && widths[0].is_finite());
    let loaded = Estimator::from_bytes(&estimator.to_bytes().unwrap()).unwrap();
    assert_eq!(loaded.intervals(), estimator.intervals());
}

/// Records every call, so the order of the stages and the counts can be
/// checked against the builder's settings.
#[derive(Default)]
struct Log(std::sync::Mutex<Vec<(twostage::Stage, &'static str, usize)>>);

impl twostage::Progress for Log {
    fn begin(&self, stage: twostage::Stage, total: usize) {
        self.0.lock().unwrap().push((stage, "begin", total));
    }
    fn advance(&self, stage: twostage::Stage, done: usize) {
        self.0.lock().unwrap().push((stage, "advance", done));
    }
    fn end(&self, stage: twostage::Stage) {
        self.0.lock().unwrap().push((stage, "end", 0));
    }
}

#[test]
fn progress_sees_every_stage_in_order_with_its_count() {
    use twostage::Stage::{Calibration, Fitting, Training, Validation};
    let model = small_benchmark();
    let log = Log::default();
    TwoStage::builder(&model)
        .compressor(Arx::new(2, 2).unwrap())
        .simulations(60)
        .calibration(25)
        .validation(15)
        .linear(1e-6)
        .unwrap()
        .progress(&log)
        .train()
        .unwrap();
    let events = log.0.into_inner().unwrap();
    // Collapse the advances of each stage into one total.
    let mut summary: Vec<(twostage::Stage, &str, usize)> = Vec::new();
    for (stage, what, n) in events {
        match summary.last_mut() {
            Some(last) if what == "advance" && last.0 == stage && last.1 == "advance" => {
                last.2 += n
            }
            _ => summary.push((stage, what, n)),
        }
    }
    assert_eq!(
        summary,
        vec![
            (Training, "begin", 60),
            (Training, "advance", 60),
            (Training, "end", 0),
            (Fitting, "begin", 0),
            (Fitting, "end", 0),
            (Calibration, "begin", 25),
            (Calibration, "advance", 25),
            (Calibration, "end", 0),
            (Validation, "begin", 15),
            (Validation, "advance", 15),
            (Validation, "end", 0),
        ]
    );
}

#[test]
fn the_automatic_design_keeps_its_best_candidate_and_is_reproducible() {
    let model = small_benchmark();
    let net = |h: usize| {
        RegressorConfig::Mlp(
            MlpParams::new(&[h])
                .unwrap()
                .restarts(2)
                .max_iterations(60)
                .check()
                .unwrap(),
        )
    };
    let run = || {
        AutoDesign::new(&model)
            .budget(twostage::Budget::Simulations(300))
            .compressors(vec![
                Arx::new(2, 2).unwrap().into(),
                Arx::new(3, 3).unwrap().into(),
                Arx::new(5, 5).unwrap().into(),
                twostage::compress::OutputPca::new(4).unwrap().into(),
            ])
            .networks(net(6), vec![net(3), net(10)])
            .settings(|b| b.seed(4).calibration(50).validation(50))
            .run()
            .unwrap()
    };
    let outcome = run();
    let scored: Vec<&twostage::CandidateReport> = outcome
        .candidates
        .iter()
        .filter(|c| c.status.is_scored())
        .collect();
    assert_eq!(
        scored.len(),
        10,
        "4 compressors, then 2 networks on the best 2, then the winner's ARX with the \
         record's level and its restarts averaged:\n{outcome}"
    );
    let leveled = &outcome.candidates[outcome.candidates.len() - 2];
    assert_eq!(leveled.round, 3, "{outcome}");
    assert!(leveled.design.contains("+level"), "{outcome}");
    let averaged = outcome.candidates.last().unwrap();
    assert_eq!(averaged.round, 3, "{outcome}");
    assert!(
        averaged.regressor.contains("averaged restarts"),
        "{outcome}"
    );
    // The round-2 winner at its own seed and two others.
    assert_eq!(outcome.seed_scores.len(), 3, "{outcome}");
    assert!(outcome.seed_scores.iter().all(|s| s.is_finite()));
    // And on half its 240 fitting rows: does more data pay?
    assert_eq!(
        outcome.half_rows.map(|(rows, _)| rows),
        Some(120),
        "{outcome}"
    );
    let best = &outcome.candidates[outcome.best];
    assert!(scored.iter().all(|c| c.score >= best.score), "{outcome}");
    assert!(outcome.candidates.iter().any(|c| c.round == 2), "{outcome}");
    assert_eq!(
        outcome.estimator.compressor().to_string(),
        best.compressor,
        "the winner is the one shipped"
    );
    // Every score is RMSE over the prior's sd (1.8 / sqrt(12)).
    for c in &scored {
        let sd = 1.8 / 12f64.sqrt();
        assert!((c.score - c.rmse[0] / sd).abs() < 1e-12, "{c:?}");
    }
    assert!(outcome.estimator.validation().is_some());
    assert_eq!(
        outcome.estimator.to_bytes().unwrap(),
        run().estimator.to_bytes().unwrap(),
        "a simulation budget gives the same estimator every time"
    );
}

/// Round 1 on a share of the rows ranks the compressors; round 2 refits
/// the round-1 network with the others on every fitting row, and only
/// those full fits compete for the win.
#[test]
fn a_screened_first_round_only_ranks_the_compressors() {
    let model = small_benchmark();
    let net = |h: usize| {
        RegressorConfig::Mlp(
            MlpParams::new(&[h])
                .unwrap()
                .restarts(1)
                .max_iterations(40)
                .check()
                .unwrap(),
        )
    };
    let outcome = AutoDesign::new(&model)
        .budget(twostage::Budget::Simulations(300))
        .screening_rows(100)
        .compressors(vec![
            Arx::new(2, 2).unwrap().into(),
            Arx::new(3, 3).unwrap().into(),
            Arx::new(5, 5).unwrap().into(),
        ])
        .networks(net(6), vec![net(3)])
        .settings(|b| b.seed(4).calibration(0).validation(0))
        .run()
        .unwrap();
    let fit_rows = 240; // 80% of 300
    let first: Vec<_> = outcome.candidates.iter().filter(|c| c.round == 1).collect();
    let second: Vec<_> = outcome.candidates.iter().filter(|c| c.round == 2).collect();
    assert_eq!(first.len(), 3, "{outcome}");
    assert!(first.iter().all(|c| c.fit_rows == 100), "{outcome}");
    assert_eq!(
        second.len(),
        4,
        "both networks on the best 2 compressors:\n{outcome}"
    );
    assert!(second.iter().all(|c| c.fit_rows == fit_rows), "{outcome}");
    assert_eq!(
        second
            .iter()
            .filter(|c| c.regressor == net(6).to_string())
            .count(),
        2,
        "the round-1 network again, on every row:\n{outcome}"
    );
    let best = &outcome.candidates[outcome.best];
    assert!(best.round >= 2, "{outcome}");
    assert!(second.iter().all(|c| c.score >= best.score), "{outcome}");
}
