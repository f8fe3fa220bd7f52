//! FMUs built from the project's C sources at test time, simulated through
//! `FmuSimulator` and compared with the same models in Rust.

#![allow(clippy::unwrap_used)]

mod common;

use common::{Model, PENDULUM_DIVISOR, PENDULUM_STEP, build, build_with, pendulum_in_rust};
use rayon::prelude::*;
use twostage_fmi::{Execution, FmiError, FmiVersion, FmuSimulator, InterfaceKind};
use twostage_models::{
    Benchmark, InputSignal, IoData, ModelSpec, Prior, Simulator, experiment_rng,
};

const N: usize = 300;

fn benchmark_spec(name: &str) -> ModelSpec {
    ModelSpec::new(
        name,
        &["theta"],
        Prior::uniform_box(&[-0.9], &[0.9]).unwrap(),
        1.0,
        N,
    )
    .unwrap()
    .with_signals(&["u"], &["y"])
}

/// eq. (5) as an FMU: the noises as inputs, drawn in the built-in model's
/// order (v2, v11, v12 each sample) with its standard deviations.
fn benchmark_fmu(fmu: &std::path::Path) -> FmuSimulator {
    FmuSimulator::builder(fmu, benchmark_spec("benchmark-fmu"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .noise_input("v2", 0.1f64.sqrt())
        .noise_input("v11", 1.0)
        .noise_input("v12", 1.0)
        .build()
        .unwrap()
}

fn simulate(sim: &dyn Simulator, theta: f64, seed: u64, index: u64) -> IoData {
    let mut record = sim.spec().new_record();
    sim.simulate(&[theta], &mut experiment_rng(seed, index), &mut record)
        .unwrap();
    record
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn the_benchmark_as_a_co_simulation_fmu_is_the_built_in_model_sample_for_sample() {
    let builtin = Benchmark::builder().n_samples(N).build().unwrap();
    for version in [FmiVersion::V2, FmiVersion::V3] {
        let fmu = build(Model::Benchmark, version);
        let sim = benchmark_fmu(&fmu.path);
        assert_eq!(sim.interface(), InterfaceKind::CoSimulation);
        for (i, theta) in [-0.85, -0.3, 0.0, 0.42, 0.9].into_iter().enumerate() {
            let ours = simulate(&sim, theta, 11, i as u64);
            let reference = simulate(&builtin, theta, 11, i as u64);
            assert!(
                same_bits(ours.input(0), reference.input(0)),
                "{version}: the input"
            );
            assert!(
                same_bits(ours.output(0), reference.output(0)),
                "FMI {version}, theta = {theta}: y differs, first at sample {:?}",
                ours.output(0)
                    .iter()
                    .zip(reference.output(0))
                    .position(|(a, b)| a.to_bits() != b.to_bits())
            );
        }
    }
}

fn worker() -> Vec<String> {
    vec![env!("CARGO_BIN_EXE_twostage-fmu-worker").to_string()]
}

#[test]
fn experiments_are_the_same_bits_whatever_the_thread_count_and_instance_policy() {
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let once = build(Model::BenchmarkOnce, FmiVersion::V2);
    let sim = benchmark_fmu(&fmu.path);
    let single = benchmark_fmu(&once.path);
    let spec = benchmark_spec("benchmark-fmu");
    let workers = FmuSimulator::builder(&once.path, spec)
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .noise_input("v2", 0.1f64.sqrt())
        .noise_input("v11", 1.0)
        .noise_input("v12", 1.0)
        .worker_processes(worker())
        .build()
        .unwrap();
    assert_eq!(sim.execution(), Execution::Threads);
    assert_eq!(
        single.execution(),
        Execution::OneAtATime,
        "declared once per process"
    );
    assert_eq!(workers.execution(), Execution::WorkerProcesses);
    let chart = |sim: &FmuSimulator, threads: usize| -> Vec<Vec<f64>> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            (0..48u64)
                .into_par_iter()
                .map(|i| {
                    simulate(sim, -0.9 + 0.0375 * i as f64, 5, i)
                        .output(0)
                        .to_vec()
                })
                .collect()
        })
    };
    let one = chart(&sim, 1);
    assert_eq!(chart(&sim, 4), one, "4 threads, 4 instances");
    // The once-per-process FMU refuses a second live instance: in this
    // process it runs one experiment at a time, or in 4 worker processes,
    // and gives the same chart either way.
    assert_eq!(chart(&single, 4), one);
    assert_eq!(chart(&workers, 4), one);
}

/// A worker let go removes the FMU it unpacked: its input is closed and it
/// ends its loop (killed, it would leave the directory in the temporary
/// folder, one per worker and run).
#[test]
fn workers_unpack_nothing_and_leave_nothing_behind() {
    let once = build(Model::BenchmarkOnce, FmiVersion::V2);
    let temporary = tempfile::tempdir().unwrap();
    let command = vec![
        "env".to_string(),
        format!("TMPDIR={}", temporary.path().display()),
        env!("CARGO_BIN_EXE_twostage-fmu-worker").to_string(),
    ];
    let workers = FmuSimulator::builder(&once.path, benchmark_spec("benchmark-fmu"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .noise_input("v2", 0.1f64.sqrt())
        .noise_input("v11", 1.0)
        .noise_input("v12", 1.0)
        .worker_processes(command)
        .build()
        .unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap();
    let outputs: Vec<f64> = pool.install(|| {
        (0..12u64)
            .into_par_iter()
            .map(|i| simulate(&workers, 0.1, 3, i).output(0)[5])
            .collect()
    });
    assert!(outputs.iter().all(|y| y.is_finite()));
    // The workers run the FMU the parent unpacked: none unpacks its own.
    let unpacked = || std::fs::read_dir(temporary.path()).unwrap().count();
    assert_eq!(unpacked(), 0, "a worker unpacked the FMU again");
    drop(workers);
    assert_eq!(unpacked(), 0);
}

#[test]
fn a_crashing_fmu_in_a_worker_fails_only_its_experiments() {
    let once = build(Model::BenchmarkOnce, FmiVersion::V3);
    // Where a worker would unpack: a crashed one could not clean it up.
    let temporary = tempfile::tempdir().unwrap();
    let mut in_temporary = vec![
        "env".to_string(),
        format!("TMPDIR={}", temporary.path().display()),
    ];
    in_temporary.extend(worker());
    let crashing = FmuSimulator::builder(&once.path, benchmark_spec("crashing"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .start("crash_at", 40.0)
        .worker_processes(in_temporary)
        .build()
        .unwrap();
    let mut record = crashing.spec().new_record();
    for i in 0..2 {
        let err = crashing
            .simulate(&[0.2], &mut experiment_rng(2, i), &mut record)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("ended without an answer") && err.contains("signal"),
            "{err}"
        );
    }
    let left = std::fs::read_dir(temporary.path()).unwrap().count();
    assert_eq!(left, 0, "crashed workers left {left} unpacked FMU(s)");
    // A step failure inside a worker comes back with the FMU's log.
    let failing = FmuSimulator::builder(&once.path, benchmark_spec("failing"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .start("fail_at", 3.0)
        .worker_processes(worker())
        .build()
        .unwrap();
    let err = failing
        .simulate(&[0.2], &mut experiment_rng(2, 0), &mut record)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("worker process: fmi3DoStep at t = 3") && err.contains("deliberate failure"),
        "{err}"
    );
}

fn pendulum_fmu(fmu: &std::path::Path, kick_at: Option<f64>) -> twostage_fmi::Result<FmuSimulator> {
    let spec = ModelSpec::new(
        "pendulum",
        &["k", "c"],
        Prior::uniform_box(&[0.5, 0.05], &[4.0, 1.0]).unwrap(),
        PENDULUM_STEP,
        200,
    )
    .unwrap()
    .with_signals(&["u"], &["y"]);
    let mut builder = FmuSimulator::builder(fmu, spec)
        .input(InputSignal::white_gaussian(0.5).unwrap())
        .step_divisor(PENDULUM_DIVISOR);
    if let Some(t) = kick_at {
        builder = builder.start("kick_at", t);
    }
    builder.build()
}

#[test]
fn a_model_exchange_fmu_matches_the_same_model_in_rust_with_the_same_step() {
    for version in [FmiVersion::V2, FmiVersion::V3] {
        let fmu = build(Model::Pendulum, version);
        let sim = pendulum_fmu(&fmu.path, None).unwrap();
        assert_eq!(sim.interface(), InterfaceKind::ModelExchange);
        for (i, (k, c)) in [(0.7, 0.1), (3.5, 0.9)].into_iter().enumerate() {
            let mut record = sim.spec().new_record();
            sim.simulate(&[k, c], &mut experiment_rng(3, i as u64), &mut record)
                .unwrap();
            let reference = pendulum_in_rust(k, c, record.input(0), None);
            let worst = record
                .output(0)
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst <= 1e-12, "FMI {version}, k = {k}: differs by {worst}");
            // The model moves: a test of equal zeros would prove nothing.
            assert!(reference.iter().any(|y| (y - 0.5).abs() > 0.1));
        }
    }
}

#[test]
fn time_events_on_the_step_grid_are_honoured_and_others_refused() {
    for version in [FmiVersion::V2, FmiVersion::V3] {
        let fmu = build(Model::Pendulum, version);
        // 2.5 s is step 200 of h = 0.0125: on the grid.
        let sim = pendulum_fmu(&fmu.path, Some(2.5)).unwrap();
        let mut record = sim.spec().new_record();
        sim.simulate(&[1.0, 0.2], &mut experiment_rng(4, 0), &mut record)
            .unwrap();
        let kicked = pendulum_in_rust(1.0, 0.2, record.input(0), Some(200));
        let unkicked = pendulum_in_rust(1.0, 0.2, record.input(0), None);
        let gap = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
        };
        assert!(gap(record.output(0), &kicked) <= 1e-12, "FMI {version}");
        assert!(gap(record.output(0), &unkicked) > 0.1, "the kick happened");
        // 2.51 s lies inside a step.
        let sim = pendulum_fmu(&fmu.path, Some(2.51)).unwrap();
        let err = sim
            .simulate(&[1.0, 0.2], &mut experiment_rng(4, 0), &mut record)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("time event at t = 2.51") && err.contains("cannot honour"),
            "{err}"
        );
    }
}

#[test]
fn a_failing_step_fails_that_experiment_and_quotes_the_fmu_log() {
    for version in [FmiVersion::V2, FmiVersion::V3] {
        let fmu = build(Model::Benchmark, version);
        let failing = FmuSimulator::builder(&fmu.path, benchmark_spec("failing"))
            .input(InputSignal::white_gaussian(1.0).unwrap())
            .start("fail_at", 17.0)
            .build()
            .unwrap();
        let mut record = failing.spec().new_record();
        let err = failing
            .simulate(&[0.3], &mut experiment_rng(1, 0), &mut record)
            .unwrap_err()
            .to_string();
        assert!(err.contains("DoStep at t = 17"), "{err}");
        assert!(err.contains("returned Error"), "{err}");
        assert!(
            err.contains("deliberate failure at t = 17 (fail_at = 17)"),
            "the log: {err}"
        );
        // The next experiment gets a fresh instance and fails the same way,
        // not with a stale state.
        let again = failing
            .simulate(&[0.3], &mut experiment_rng(1, 1), &mut record)
            .unwrap_err()
            .to_string();
        assert!(again.contains("t = 17"), "{again}");
    }
}

#[test]
fn a_step_size_the_fmu_refuses_is_reported_with_its_reason() {
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let sim = FmuSimulator::builder(&fmu.path, benchmark_spec("halves"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .step_divisor(2)
        .build()
        .unwrap();
    let mut record = sim.spec().new_record();
    let err = sim
        .simulate(&[0.3], &mut experiment_rng(1, 0), &mut record)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not h = 0.5"), "{err}");
}

fn build_error(fmu: &std::path::Path, spec: ModelSpec) -> FmiError {
    FmuSimulator::builder(fmu, spec)
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .build()
        .unwrap_err()
}

#[test]
fn names_that_do_not_fit_their_role_are_refused_with_the_reason() {
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let spec = |params: &[&str], inputs: &[&str], outputs: &[&str]| {
        let lo = vec![0.0; params.len()];
        let hi = vec![1.0; params.len()];
        ModelSpec::new("x", params, Prior::uniform_box(&lo, &hi).unwrap(), 1.0, 10)
            .unwrap()
            .with_signals(inputs, outputs)
    };
    type Case<'a> = (&'a [&'a str], &'a [&'a str], &'a [&'a str], &'a str);
    let cases: [Case<'_>; 6] = [
        (
            &["Theta"],
            &["u"],
            &["y"],
            "no variable of that name (similar: theta)",
        ),
        (&["a"], &["u"], &["y"], "calculatedParameter"),
        (
            &["y"],
            &["u"],
            &["y"],
            "it is a continuous output variable, so it cannot be estimated",
        ),
        (
            &["theta"],
            &["theta"],
            &["y"],
            "named as a parameter to estimate and as an input",
        ),
        (
            &["theta"],
            &["x1"],
            &["y"],
            "local variable, so it cannot be an input",
        ),
        (&["theta"], &["u"], &["fail_at"], "so it cannot be measured"),
    ];
    for (params, inputs, outputs, expected) in cases {
        let err = build_error(&fmu.path, spec(params, inputs, outputs));
        assert!(matches!(err, FmiError::Variable { .. }), "{err}");
        assert!(err.to_string().contains(expected), "{expected}: {err}");
    }
}

#[test]
fn broken_fmus_are_answered_clearly() {
    let spec = || benchmark_spec("broken");
    let dir = tempfile::tempdir().unwrap();
    // Not a zip.
    let text = dir.path().join("notes.fmu");
    std::fs::write(&text, "model notes, not an FMU").unwrap();
    let err = build_error(&text, spec());
    assert!(
        matches!(err, FmiError::NotAnArchive { .. }) && err.to_string().contains("zip"),
        "{err}"
    );
    // An FMU cut short (a download that stopped half way).
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let whole = std::fs::read(&fmu.path).unwrap();
    let cut = dir.path().join("cut.fmu");
    std::fs::write(&cut, &whole[..whole.len() / 2]).unwrap();
    let err = build_error(&cut, spec());
    assert!(
        matches!(err, FmiError::NotAnArchive { .. })
            && err.to_string().contains("the zip archive is damaged"),
        "{err}"
    );
    // A description far larger than any (sparse: nothing is written),
    // refused by its size before it is read.
    let huge = dir.path().join("huge");
    std::fs::create_dir_all(&huge).unwrap();
    std::fs::File::create(huge.join("modelDescription.xml"))
        .unwrap()
        .set_len(300_000_000)
        .unwrap();
    let err = build_error(&huge, spec()).to_string();
    assert!(
        err.contains(
            "modelDescription.xml takes 300.0 MB where a description takes at most 268.4 MB"
        ),
        "{err}"
    );
    // A zip without a description.
    let fmu = build_with(Model::Benchmark, FmiVersion::V2, |root| {
        std::fs::remove_file(root.join("modelDescription.xml")).unwrap();
    });
    let err = build_error(&fmu.path, spec());
    assert!(err.to_string().contains("no modelDescription.xml"), "{err}");
    // No binary for this platform.
    let fmu = build_with(Model::Benchmark, FmiVersion::V2, |root| {
        std::fs::rename(root.join("binaries/linux64"), root.join("binaries/win64")).unwrap();
    });
    let err = build_error(&fmu.path, spec());
    assert!(matches!(err, FmiError::NoBinary { .. }), "{err}");
    assert!(
        err.to_string().contains("binaries/linux64/benchmark.so")
            && err.to_string().contains("win64"),
        "{err}"
    );
    // FMI 1.0.
    let fmu = build_with(Model::Benchmark, FmiVersion::V2, |root| {
        let path = root.join("modelDescription.xml");
        let xml = std::fs::read_to_string(&path)
            .unwrap()
            .replace("fmiVersion=\"2.0\"", "fmiVersion=\"1.0\"");
        std::fs::write(path, xml).unwrap();
    });
    let err = build_error(&fmu.path, spec());
    assert!(matches!(err, FmiError::UnsupportedVersion { .. }), "{err}");
    // A token the binary does not know.
    let fmu = build_with(Model::Benchmark, FmiVersion::V3, |root| {
        let path = root.join("modelDescription.xml");
        let xml = std::fs::read_to_string(&path)
            .unwrap()
            .replace("{twostage-benchmark-1}", "{other}");
        std::fs::write(path, xml).unwrap();
    });
    let err = build_error(&fmu.path, spec()).to_string();
    assert!(
        err.contains("instantiate") && err.contains("token does not match"),
        "{err}"
    );
    // A missing interface.
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let err = FmuSimulator::builder(&fmu.path, spec())
        .interface(InterfaceKind::ModelExchange)
        .build()
        .unwrap_err();
    assert!(
        err.to_string().contains("no model exchange interface"),
        "{err}"
    );
    // State events under model exchange.
    let fmu = build_with(Model::Pendulum, FmiVersion::V2, |root| {
        let path = root.join("modelDescription.xml");
        let xml = std::fs::read_to_string(&path).unwrap().replace(
            "numberOfEventIndicators=\"0\"",
            "numberOfEventIndicators=\"2\"",
        );
        std::fs::write(path, xml).unwrap();
    });
    let err = pendulum_fmu(&fmu.path, None).unwrap_err();
    assert!(err.to_string().contains("2 event indicator(s)"), "{err}");
}

#[test]
fn inputs_are_held_between_samples_unless_the_fmu_interpolates_them() {
    let spec = || {
        ModelSpec::new(
            "integrator",
            &["gain"],
            Prior::uniform_box(&[0.5], &[2.0]).unwrap(),
            0.1,
            50,
        )
        .unwrap()
        .with_signals(&["u"], &["y"])
    };
    for (interpolates, divisor) in [(false, 1), (true, 1), (true, 3)] {
        let fmu = build(Model::Integrator(interpolates), FmiVersion::V2);
        let sim = FmuSimulator::builder(&fmu.path, spec())
            .input(InputSignal::white_gaussian(1.0).unwrap())
            .step_divisor(divisor)
            .build()
            .unwrap();
        assert_eq!(sim.interpolates_inputs(), interpolates);
        let mut record = sim.spec().new_record();
        sim.simulate(&[1.5], &mut experiment_rng(6, 0), &mut record)
            .unwrap();
        let (u, y) = (record.input(0), record.output(0));
        // y' = 1.5 u: held, each sample adds 1.5 u[k] h; on the straight
        // line, the trapezoid 1.5 h (u[k] + u[k+1]) / 2, exactly.
        let mut expected = 0.0;
        for k in 0..u.len() {
            assert!(
                (y[k] - expected).abs() <= 1e-12,
                "interpolates {interpolates}, d = {divisor}, sample {k}: {} vs {expected}",
                y[k]
            );
            if k + 1 < u.len() {
                expected += 1.5
                    * 0.1
                    * if interpolates {
                        0.5 * (u[k] + u[k + 1])
                    } else {
                        u[k]
                    };
            }
        }
    }
}

#[test]
fn after_a_fatal_status_the_fmu_is_not_called_again() {
    let fmu = build(Model::Benchmark, FmiVersion::V2);
    let sim = FmuSimulator::builder(&fmu.path, benchmark_spec("fatal"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .start("fail_at", 9.0)
        .start("fail_fatally", 1.0)
        .build()
        .unwrap();
    let mut record = sim.spec().new_record();
    let err = sim
        .simulate(&[0.1], &mut experiment_rng(8, 0), &mut record)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("fmi2DoStep at t = 9 returned Fatal")
            && err.contains("Fatal [twostage-test]: deliberate failure"),
        "{err}"
    );
    let err = sim
        .simulate(&[0.1], &mut experiment_rng(8, 1), &mut record)
        .unwrap_err()
        .to_string();
    assert!(err.contains("an earlier call returned Fatal"), "{err}");

    // In a worker process, the worker that saw Fatal retires: the next
    // experiment runs in a fresh process and meets the same failure, not a
    // refusal.
    let once = build(Model::BenchmarkOnce, FmiVersion::V2);
    let sim = FmuSimulator::builder(&once.path, benchmark_spec("fatal"))
        .input(InputSignal::white_gaussian(1.0).unwrap())
        .start("fail_at", 9.0)
        .start("fail_fatally", 1.0)
        .worker_processes(worker())
        .build()
        .unwrap();
    for i in 0..2 {
        let err = sim
            .simulate(&[0.1], &mut experiment_rng(8, i), &mut record)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("t = 9 returned Fatal"),
            "experiment {i}: {err}"
        );
    }
}
