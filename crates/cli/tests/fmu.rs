//! From an FMU to a validated estimator on the command line: `fmu
//! inspect` lists what the FMU offers and writes a model file that
//! `train` and `validate` take as it is.
#![allow(clippy::unwrap_used)]

mod common;
#[path = "../../fmi/tests/common/mod.rs"]
mod fmus;

use common::{path, scratch, text, twostage};
use twostage::fmi::FmiVersion;

#[test]
fn inspect_lists_the_roles_and_writes_a_model_file_that_trains_and_validates() {
    let fmu = fmus::build(fmus::Model::Benchmark, FmiVersion::V3);
    let dir = scratch("fmu-inspect");
    std::fs::create_dir_all(dir.join("fmus")).unwrap();
    std::fs::create_dir_all(dir.join("models")).unwrap();
    let copy = dir.join("fmus/benchmark.fmu");
    std::fs::copy(&fmu.path, &copy).unwrap();
    let model = dir.join("models/benchmark.toml");

    let out = twostage(&["fmu", "inspect", path(&copy), "--write", path(&model)]);
    let listing = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(listing.contains("FMU: benchmark (FMI 3.0)"), "{listing}");
    let section = |title: &str| {
        let start = listing
            .find(title)
            .unwrap_or_else(|| panic!("no {title}: {listing}"));
        let rest = &listing[start..];
        rest[..rest[1..].find("\n\n").map_or(rest.len(), |e| e + 1)].to_string()
    };
    let parameters = section("parameters");
    assert!(
        parameters.contains("theta") && parameters.contains("fail_at"),
        "{parameters}"
    );
    assert!(
        !parameters.contains(" a "),
        "a calculated parameter is not offered: {parameters}"
    );
    let inputs = section("inputs");
    assert!(
        ["u", "v2", "v11", "v12"].iter().all(|i| inputs.contains(i)),
        "{inputs}"
    );
    assert!(section("outputs").contains("measured output"));
    assert!(listing.contains("2 local real variable(s)"), "{listing}");

    // The file starts from the FMU's suggested experiment. As its CHECK
    // lines ask, the modeller moves the disturbances to noise inputs (with
    // every noise measured, y is an exact function of the lagged signals
    // and ARX refuses the rank-deficient regressors) and drops fail_at.
    let written = std::fs::read_to_string(&model).unwrap();
    assert!(
        written.contains("fmu = \"../fmus/benchmark.fmu\"") && written.contains("samples = 300"),
        "{written}"
    );
    let fail_at = "[[parameter]]\nname = \"fail_at\"\n# CHECK: start value -1: fail the step at this time\nprior = { dist = \"uniform\", low = -1.5, high = -0.5 }\n";
    assert!(written.contains(fail_at), "{written}");
    let edited = written
        .replace(fail_at, "")
        .replace("inputs = [\"u\", \"v2\", \"v11\", \"v12\"]", "inputs = [\"u\"]")
        .replace(
            "# No [[preset]]",
            "[noise]\ninputs = [{ name = \"v2\", sd = 0.3 }, { name = \"v11\", sd = 1.0 }, { name = \"v12\", sd = 1.0 }]\n\n# No [[preset]]",
        );
    assert!(
        !written.contains("\n[[preset]]"),
        "no preset to train: {written}"
    );
    // The model file and its FMU move together: the path is relative.
    let moved = dir.join("moved");
    std::fs::create_dir_all(moved.join("models")).unwrap();
    std::fs::create_dir_all(moved.join("fmus")).unwrap();
    std::fs::rename(&copy, moved.join("fmus/benchmark.fmu")).unwrap();
    let copy = moved.join("fmus/benchmark.fmu");
    let model = moved.join("models/benchmark.toml");
    std::fs::write(&model, edited).unwrap();
    let estimator = dir.join("e.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--sims",
        "400",
        "--validate",
        "100",
        "--calibrate",
        "0",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr)
            .contains("has no preset: searching for a design (automatic design, 400 simulations"),
        "{}",
        text(&out.stderr)
    );
    let out = twostage(&[
        "validate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--sims",
        "100",
    ]);
    let report = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(report.contains("theta"), "{report}");

    // A second --write refuses to overwrite.
    let out = twostage(&["fmu", "inspect", path(&copy), "--write", path(&model)]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("may exist already"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn inspect_answers_a_file_that_is_not_an_fmu() {
    let dir = scratch("fmu-not");
    let file = dir.join("notes.fmu");
    std::fs::write(&file, "not a zip").unwrap();
    let out = twostage(&["fmu", "inspect", path(&file)]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("is not an FMU") && err.contains("zip"),
        "{err}"
    );
}

/// An FMU built for another platform is described, and the exit code and
/// a line say it cannot run here; a binary that does not load says the
/// loader's reason, not only that loading failed.
#[test]
fn an_fmu_that_cannot_run_here_says_so() {
    let dir = scratch("fmu-elsewhere");
    let elsewhere = fmus::build_with(fmus::Model::Benchmark, FmiVersion::V2, |root| {
        let binaries = root.join("binaries");
        let here = std::fs::read_dir(&binaries)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        std::fs::rename(here, binaries.join("win64")).unwrap();
    });
    let copy = dir.join("elsewhere.fmu");
    std::fs::copy(&elsewhere.path, &copy).unwrap();
    let out = twostage(&["fmu", "inspect", path(&copy)]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("binary: none for this platform"),
        "{}",
        text(&out.stdout)
    );
    assert!(
        text(&out.stderr).contains("found binaries for win64"),
        "{}",
        text(&out.stderr)
    );
    // A binary that is not a shared library: the loader says why.
    let broken = fmus::build_with(fmus::Model::Benchmark, FmiVersion::V2, |root| {
        let binaries = root.join("binaries");
        let here = std::fs::read_dir(&binaries)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let library = std::fs::read_dir(&here)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        std::fs::write(library, b"not a shared library").unwrap();
    });
    let simulator = twostage::fmi::FmuSimulator::builder(
        &broken.path,
        twostage::models::Simulator::spec(&twostage::models::Benchmark::new()).clone(),
    )
    .input(twostage::models::InputSignal::white_gaussian(1.0).unwrap())
    .build()
    .unwrap_err()
    .to_string();
    assert!(simulator.contains("cannot be loaded"), "{simulator}");
    assert!(
        simulator.contains("file too short") || simulator.contains("invalid ELF header"),
        "the loader's own reason: {simulator}"
    );
}

/// The binary is its own FMU worker: started with `TWOSTAGE_FMU_WORKER`
/// set it serves a parent on stdin and stdout (here one that says nothing,
/// which it names), instead of parsing its arguments.
#[test]
fn the_binary_serves_as_an_fmu_worker_when_started_as_one() {
    use std::process::{Command, Stdio};
    let out = Command::new(env!("CARGO_BIN_EXE_twostage"))
        .env("TWOSTAGE_FMU_WORKER", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("the parent did not start with a set-up"),
        "{}",
        text(&out.stderr)
    );
    // Started without it, the same binary is the command line.
    let out = Command::new(env!("CARGO_BIN_EXE_twostage"))
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}

/// An FMU that allows one instance per process trains through worker
/// processes of the binary (started as an FMU worker), to the same estimator
/// as the same FMU without the restriction.
#[test]
fn a_once_per_process_fmu_trains_in_worker_processes_to_the_same_estimator() {
    let dir = scratch("fmu-once");
    let mut reports = Vec::new();
    for (name, model) in [
        ("free", fmus::Model::Benchmark),
        ("once", fmus::Model::BenchmarkOnce),
    ] {
        let fmu = fmus::build(model, FmiVersion::V2);
        let copy = dir.join(format!("{name}.fmu"));
        std::fs::copy(&fmu.path, &copy).unwrap();
        let model = dir.join(format!("{name}.toml"));
        std::fs::write(
            &model,
            format!(
                r#"[model]
name = "benchmark"
[source]
fmu = "{name}.fmu"
[[parameter]]
name = "theta"
prior = {{ dist = "uniform", low = -0.9, high = 0.9 }}
[signals]
inputs = ["u"]
outputs = ["y"]
samples = 300
sample_time = 1.0
[input]
signal = "white"
sd = 1.0
[noise]
inputs = [{{ name = "v2", sd = 0.3 }}, {{ name = "v11", sd = 1.0 }}, {{ name = "v12", sd = 1.0 }}]
[[preset]]
name = "small"
compress = "arx:3,3"
fit = "mlp:6"
sims = 300
"#
            ),
        )
        .unwrap();
        let out = twostage(&[
            "train",
            "--model-file",
            path(&model),
            "--validate",
            "100",
            "--calibrate",
            "0",
            "--out",
            path(&dir.join(format!("{name}.tsest"))),
        ]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        let report = text(&out.stdout);
        let rmse: Vec<String> = report
            .lines()
            .filter(|l| l.contains("theta"))
            .map(str::to_string)
            .collect();
        assert!(!rmse.is_empty(), "{report}");
        reports.push(rmse);
    }
    assert_eq!(
        reports[0], reports[1],
        "the same chart, the same estimator, the same report"
    );
    let listing = text(&twostage(&["fmu", "inspect", path(&dir.join("once.fmu"))]).stdout);
    assert!(listing.contains("worker processes"), "{listing}");
}

/// Every test FMU with a parameter to estimate: the file `fmu inspect
/// --write` saves trains as written, with no edit, whatever its
/// interface; without a preset it searches (the automatic design on a
/// few simulations, for one of them: the search is the same code for
/// every source, and it costs half a minute a model).
#[test]
fn every_written_model_file_trains_as_written() {
    for (model, version, name, stages) in [
        (fmus::Model::Pendulum, FmiVersion::V2, "pendulum", None),
        (
            fmus::Model::Integrator(false),
            FmiVersion::V2,
            "integrator",
            Some(["--compress", "arx:2,1", "--fit", "mlp:4"]),
        ),
        (
            fmus::Model::Benchmark,
            FmiVersion::V3,
            "benchmark",
            Some(["--compress", "arx:2,1", "--fit", "mlp:4"]),
        ),
    ] {
        let fmu = fmus::build(model, version);
        let dir = scratch(&format!("fmu-as-written-{name}"));
        let model_file = dir.join(format!("{name}.toml"));
        let out = twostage(&[
            "fmu",
            "inspect",
            path(&fmu.path),
            "--write",
            path(&model_file),
        ]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        let estimator = dir.join("e.tsest");
        let mut args = vec![
            "train",
            "--model-file",
            path(&model_file),
            "--sims",
            "300",
            "--validate",
            "60",
            "--calibrate",
            "0",
            "--out",
            path(&estimator),
        ];
        args.extend(stages.iter().flatten());
        let out = twostage(&args);
        let stderr = text(&out.stderr);
        assert!(out.status.success(), "{name}: {stderr}");
        let report = text(&out.stdout);
        assert!(!report.contains("failed:"), "{name}: {report}");
        if stages.is_none() {
            assert!(
                stderr.contains("has no preset: searching"),
                "{name}: {stderr}"
            );
            assert!(report.contains("[[preset]]"), "{name}: {report}");
        } else {
            assert!(report.contains("r = 60 records unseen"), "{name}: {report}");
        }
    }
}
