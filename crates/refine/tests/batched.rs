//! Output-error descents through a simulator that counts its requests:
//! the descents of a refinement go to it together, a round at a time, and
//! end where each descent alone ends.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::sync::atomic::{AtomicUsize, Ordering};

use twostage_models::{
    Block, BlockInputs, Capabilities, Conditions, ExperimentRng, IoData, ModelSpec, Prior,
    SimError, Simulator, experiment_rng, simulate_one_by_one,
};
use twostage_refine::{OutputError, Refinement, TerminationReason};

/// `y(t) = a y(t-1) + b u(t-1)` on the given input, noise-free only; it
/// counts requests and points, and fails at `b` above `fail_above`.
struct FirstOrder {
    spec: ModelSpec,
    batch: usize,
    fail_above: f64,
    requests: AtomicUsize,
    points: AtomicUsize,
}

impl FirstOrder {
    fn new(batch: usize, fail_above: f64) -> Self {
        let prior = Prior::uniform_box(&[0.0, 0.1], &[0.95, 3.0]).unwrap();
        let spec = ModelSpec::new("first-order", &["a", "b"], prior, 1.0, 300)
            .unwrap()
            .with_signals(&["u"], &["y"]);
        Self {
            spec,
            batch,
            fail_above,
            requests: AtomicUsize::new(0),
            points: AtomicUsize::new(0),
        }
    }

    fn respond(&self, theta: &[f64], input: &IoData, out: &mut IoData) -> Result<(), SimError> {
        self.points.fetch_add(1, Ordering::Relaxed);
        if theta[1] > self.fail_above {
            return Err(SimError::InvalidData(format!("b = {} breaks it", theta[1])));
        }
        let n = input.n_samples();
        out.resize(n, 1, 1);
        out.input_mut(0).copy_from_slice(input.input(0));
        let mut y = 0.0;
        for t in 0..n {
            out.output_mut(0)[t] = y;
            y = theta[0] * y + theta[1] * input.input(0)[t];
        }
        Ok(())
    }
}

impl Simulator for FirstOrder {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }
    fn batch_size(&self) -> usize {
        self.batch
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            noiseless: true,
            given_input: true,
        }
    }
    fn simulate_one(
        &self,
        theta: &[f64],
        _: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        let input = conditions
            .input
            .ok_or(SimError::InvalidData("no input".into()))?;
        self.respond(theta, input, out)
    }
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<(), SimError>> {
        if let BlockInputs::Each(_) = block.inputs {
            return simulate_one_by_one(self, thetas, rngs, block, outs);
        }
        let conditions = block.conditions(0);
        assert!(
            thetas.len() <= self.batch,
            "a request larger than the batch"
        );
        self.requests.fetch_add(1, Ordering::Relaxed);
        let Some(input) = conditions.input else {
            return vec![Err(SimError::InvalidData("no input".into())); thetas.len()];
        };
        thetas
            .iter()
            .zip(outs)
            .map(|(theta, out)| self.respond(theta, input, out))
            .collect()
    }
}

/// A record of the system at a = 0.8, b = 1.5 with a little output noise.
fn record() -> IoData {
    use rand::RngExt;
    let model = FirstOrder::new(1, f64::INFINITY);
    let mut rng = experiment_rng(11, 0);
    let u: Vec<f64> = (0..300).map(|_| rng.random_range(-1.0..1.0)).collect();
    let input = IoData::siso(&u, &vec![0.0; 300]).unwrap();
    let mut out = IoData::default();
    model.respond(&[0.8, 1.5], &input, &mut out).unwrap();
    for y in out.output_mut(0) {
        *y += 0.05 * rng.random_range(-1.0..1.0);
    }
    out
}

fn bits(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn descents_asked_together_end_where_each_ends_alone_in_far_fewer_requests() {
    let record = record();
    let starts = vec![vec![0.5, 1.0], vec![0.9, 2.5], vec![0.2, 0.5]];
    // Each start alone, one point per request.
    let alone: Vec<_> = starts
        .iter()
        .map(|start| {
            let model = FirstOrder::new(1, f64::INFINITY);
            let fit = Refinement::new(OutputError::new(&model).unwrap());
            let found = fit.descend(&record, start.clone()).unwrap();
            (found, model.requests.into_inner())
        })
        .collect();
    let one_at_a_time: usize = alone.iter().map(|(_, requests)| requests).sum();
    // All three together, through a simulator that takes 50 a request, on
    // one thread (more threads split a round's points over as many
    // requests, so that a simulator that does not vectorize uses them).
    let batched = FirstOrder::new(50, f64::INFINITY);
    let fit = Refinement::new(OutputError::new(&batched).unwrap());
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let together = one_thread
        .install(|| fit.descents_from(&record, starts.clone()))
        .unwrap();
    for ((found, _), with) in alone.iter().zip(&together) {
        assert_eq!(bits(&with.theta), bits(&found.theta));
        assert_eq!(with.loss.to_bits(), found.loss.to_bits());
        assert_eq!((with.iterations, with.stop), (found.iterations, found.stop));
        assert!((with.theta[0] - 0.8).abs() < 0.01 && (with.theta[1] - 1.5).abs() < 0.02);
    }
    let requests = batched.requests.load(Ordering::Relaxed);
    let points = batched.points.load(Ordering::Relaxed);
    // A round asks for every descent's Jacobian (2 points each) or trial
    // steps (3 each): two requests per iteration of the longest descent,
    // and one more where all three dampings were refused, where one at a
    // time each point was a request.
    let longest = together.iter().map(|d| d.iterations).max().unwrap();
    assert!(
        requests <= 3 * longest + 1,
        "{requests} requests for {longest} iterations"
    );
    assert!(
        requests * 4 < one_at_a_time,
        "{requests} requests batched against {one_at_a_time} one at a time"
    );
    // The trial dampings asked for beside the one taken cost some points.
    assert!(points <= 2 * one_at_a_time, "{points} points");
    // On two threads each round is two requests, and the same bits.
    let split = FirstOrder::new(50, f64::INFINITY);
    let fit = Refinement::new(OutputError::new(&split).unwrap());
    let two_threads = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let again = two_threads
        .install(|| fit.descents_from(&record, starts))
        .unwrap();
    for (a, b) in again.iter().zip(&together) {
        assert_eq!(bits(&a.theta), bits(&b.theta));
    }
    assert_eq!(split.requests.load(Ordering::Relaxed), 2 * requests);
}

#[test]
fn a_point_the_simulator_cannot_run_is_a_refused_step_not_a_lost_batch() {
    let record = record();
    // b above 2.0 fails: the descent from b = 2.9 must step down into the
    // region that runs; the one from 1.0 is unaffected by its batch mate's
    // failures.
    let model = FirstOrder::new(50, 2.0);
    let fit = Refinement::new(OutputError::new(&model).unwrap());
    let found = fit.descents_from(&record, vec![vec![0.5, 1.0], vec![0.85, 2.9]]);
    let found = found.unwrap_err();
    // The start itself cannot run: that descent, and so the call, fails
    // with the simulator's reason.
    assert!(found.to_string().contains("b = 2.9 breaks it"), "{found}");
    let from_inside = fit
        .descents_from(&record, vec![vec![0.5, 1.0], vec![0.75, 1.99]])
        .unwrap();
    for descent in &from_inside {
        assert!((descent.theta[1] - 1.5).abs() < 0.02, "{descent:?}");
        assert_ne!(descent.stop, TerminationReason::EvaluationFailed);
    }
    // A Jacobian point outside what the simulator can run ends that
    // descent where it stands, with its reason.
    let edge = FirstOrder::new(50, 1.5 + 1e-7);
    let fit = Refinement::new(OutputError::new(&edge).unwrap());
    let stopped = fit.descend(&record, vec![0.8, 1.5]).unwrap();
    assert_eq!(stopped.stop, TerminationReason::EvaluationFailed);
    assert!((stopped.theta[1] - 1.5).abs() < 1e-12, "{stopped:?}");
}

/// Records of one input with their own noise (the input of `record()`).
fn records_of_one_input(count: u64) -> Vec<IoData> {
    use rand::RngExt;
    let base = record();
    (0..count)
        .map(|k| {
            let mut out = base.clone();
            let mut rng = experiment_rng(12, k);
            for y in out.output_mut(0) {
                *y += 0.05 * rng.random_range(-1.0..1.0);
            }
            out
        })
        .collect()
}

#[test]
fn records_refined_together_end_where_each_ends_alone_in_fewer_requests() {
    let records = records_of_one_input(4);
    let starts = vec![vec![0.5, 1.0], vec![0.9, 2.5]];
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let alone_model = FirstOrder::new(50, f64::INFINITY);
    let fit = Refinement::new(OutputError::new(&alone_model).unwrap());
    let (alone, alone_local): (Vec<_>, Vec<_>) = one_thread.install(|| {
        records
            .iter()
            .map(|r| {
                let found = fit.descents_from(r, starts.clone()).unwrap();
                let local = fit.uncertainty(r, &found[0].theta).unwrap();
                (found, local)
            })
            .unzip()
    });
    let alone_requests = alone_model.requests.load(Ordering::Relaxed);
    let together_model = FirstOrder::new(50, f64::INFINITY);
    let fit = Refinement::new(OutputError::new(&together_model).unwrap());
    let (together, together_local) = one_thread.install(|| {
        let found: Vec<Vec<_>> = fit
            .descents_of_records(records.iter().map(|r| (r, starts.clone())).collect())
            .into_iter()
            .map(Result::unwrap)
            .collect();
        let estimates: Vec<(&IoData, &[f64])> = records
            .iter()
            .zip(&found)
            .map(|(r, d)| (r, d[0].theta.as_slice()))
            .collect();
        let local: Vec<_> = fit
            .uncertainties(&estimates)
            .into_iter()
            .map(Result::unwrap)
            .collect();
        (found, local)
    });
    for (a, b) in alone.iter().flatten().zip(together.iter().flatten()) {
        assert_eq!(bits(&a.theta), bits(&b.theta));
        assert_eq!((a.iterations, a.stop), (b.iterations, b.stop));
    }
    for (a, b) in alone_local.iter().zip(&together_local) {
        assert_eq!(bits(&a.sd), bits(&b.sd));
        assert_eq!(bits(&a.correlation), bits(&b.correlation));
    }
    let together_requests = together_model.requests.load(Ordering::Relaxed);
    assert!(
        2 * together_requests < alone_requests,
        "{together_requests} requests together against {alone_requests} record by record"
    );
}

/// The check of a two-stage estimate, the refinement and the check of the
/// refined estimate read one search: the search's points, then each
/// check's noisy references, and nothing else (the noise-free responses
/// at the estimate and at the best fit are read back from the search's
/// residuals). Descents that meet stop, and the search's
/// points are fewer than the same starts' run apart.
#[test]
fn one_search_serves_the_check_and_the_refinement() {
    use twostage_refine::{CheckPlan, SearchStarts, check_against, search_best_fits};
    let record = record();
    let model = FirstOrder::new(50, f64::INFINITY);
    let estimate = [0.6, 1.2];
    let search = SearchStarts {
        from_prior: 6,
        seed: 0,
    };
    let starts = search
        .starts(model.spec().prior(), &estimate, Some(&[0.2, 0.5]))
        .unwrap();
    assert_eq!(starts.len(), 9);
    let points = || model.points.load(Ordering::Relaxed);
    let found = search_best_fits(&model, vec![(&record, starts.clone())])
        .pop()
        .unwrap()
        .unwrap();
    let searched = points();
    assert!((found.best.theta[0] - 0.8).abs() < 0.01, "{found:?}");
    // A convex loss: every descent ends in one optimum, most of them
    // stopped where they met another.
    assert_eq!(found.optima.len(), 1);
    assert_eq!((found.optima[0].descents, found.descents), (9, 9));
    // The same starts run apart cost more points.
    let apart = FirstOrder::new(50, f64::INFINITY);
    Refinement::new(OutputError::new(&apart).unwrap())
        .descents_from(&record, starts)
        .unwrap();
    let apart = apart.points.load(Ordering::Relaxed);
    assert!(
        searched < apart,
        "{searched} points searched, {apart} apart"
    );
    // A check of the estimate: its noisy runs (this model has none of its
    // own noise, so no run misses as the record does and all of them run)
    // and the 2q noise-free points of the response's span at the estimate
    // (central differences), nothing else.
    let plan = CheckPlan {
        noisy: 99,
        seed: 0,
        score_from: 0,
        score_to: None,
        prior_starts: 6,
    };
    let first = check_against(&model, &record, &estimate, &found, plan).unwrap();
    let checked = points() - searched;
    assert_eq!(checked, first.reference_runs + 4);
    // The refined estimate is the search's best: its check adds its noisy
    // runs and its span's points, no other noise-free run and no descent.
    let refined = found.best.theta.clone();
    let second = check_against(&model, &record, &refined, &found, plan).unwrap();
    assert_eq!(points() - searched - checked, second.reference_runs + 4);
    // The responses read back are the simulated ones, to rounding.
    for (theta, check) in [(&estimate[..], &first), (&refined[..], &second)] {
        let mut direct = IoData::default();
        let quiet = twostage_models::Conditions {
            noiseless: true,
            input: Some(&record),
        };
        model
            .simulate_under(theta, &mut experiment_rng(0, 0), quiet, &mut direct)
            .unwrap();
        for (a, b) in check.simulated.output(0).iter().zip(direct.output(0)) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
        }
    }
    assert_eq!(second.loss_ratio.to_bits(), 1.0f64.to_bits());
    assert!(first.loss_ratio > 1.0 && !first.explained());
}
