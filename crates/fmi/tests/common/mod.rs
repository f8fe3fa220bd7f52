//! Test FMUs built at test time from the C sources in tests/fmus with the
//! system's C compiler, described and zipped as an exporting tool would.
#![allow(dead_code, clippy::unwrap_used)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use twostage_fmi::{FmiVersion, platform_folder};
use twostage_models::{OdeSystem, Rk4};

/// A built FMU in its own temporary folder.
pub struct TestFmu {
    pub path: PathBuf,
    _dir: tempfile::TempDir,
}

/// Which test model, and how it is packaged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Model {
    /// eq. (5), co-simulation.
    Benchmark,
    /// eq. (5), co-simulation, refusing a second instance in a process.
    BenchmarkOnce,
    /// The damped pendulum, model exchange.
    Pendulum,
    /// An integrator, FMI 2.0 co-simulation; `true`: it declares that it
    /// interpolates inputs.
    Integrator(bool),
}

/// The C sources, from any package of the workspace.
fn sources() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|dir| dir.join("crates/fmi/tests/fmus"))
        .find(|dir| dir.is_dir())
        .expect("the workspace holds crates/fmi/tests/fmus")
}

/// Compile `model` for `version` into a shared library at `binary`.
pub fn compile(model: Model, version: FmiVersion, binary: &Path) {
    let (source, once) = match model {
        Model::Benchmark => ("benchmark.c", false),
        Model::BenchmarkOnce => ("benchmark.c", true),
        Model::Pendulum => ("pendulum.c", false),
        Model::Integrator(_) => ("integrator.c", false),
    };
    std::fs::create_dir_all(binary.parent().unwrap()).unwrap();
    let mut gcc = Command::new(std::env::var("CC").unwrap_or_else(|_| "gcc".into()));
    gcc.args([
        "-shared",
        "-fPIC",
        "-O2",
        "-ffp-contract=off",
        "-std=c99",
        "-fvisibility=hidden",
    ])
    .arg("-I")
    .arg(sources())
    .arg(sources().join(source))
    .arg("-o")
    .arg(binary)
    .arg("-lm");
    if version == FmiVersion::V3 {
        gcc.arg("-DFMI3");
    }
    if once {
        gcc.arg("-DONCE");
    }
    let status = gcc.status().expect("a C compiler (gcc) runs");
    assert!(status.success(), "compiling {source} failed");
}

/// The identifier (binary name) of `model`.
pub fn identifier(model: Model) -> &'static str {
    match model {
        Model::Benchmark | Model::BenchmarkOnce => "benchmark",
        Model::Pendulum => "pendulum",
        Model::Integrator(_) => "integrator",
    }
}

/// The modelDescription.xml of `model` for `version`.
pub fn description(model: Model, version: FmiVersion) -> String {
    let id = identifier(model);
    let once = model == Model::BenchmarkOnce;
    let (token, interface, variables, structure) = match model {
        Model::Benchmark | Model::BenchmarkOnce => (
            "{twostage-benchmark-1}",
            format!(
                "<CoSimulation modelIdentifier=\"{id}\" canHandleVariableCommunicationStepSize=\"true\" canBeInstantiatedOnlyOncePerProcess=\"{once}\"/>"
            ),
            vec![
                (
                    "theta",
                    0,
                    "parameter",
                    "fixed",
                    Some(0.0),
                    "the parameter of eq. (5)",
                ),
                ("u", 1, "input", "continuous", Some(0.0), "input"),
                (
                    "v2",
                    2,
                    "input",
                    "continuous",
                    Some(0.0),
                    "measurement noise",
                ),
                (
                    "v11",
                    3,
                    "input",
                    "continuous",
                    Some(0.0),
                    "process noise of x1",
                ),
                (
                    "v12",
                    4,
                    "input",
                    "continuous",
                    Some(0.0),
                    "process noise of x2",
                ),
                ("y", 5, "output", "continuous", None, "measured output"),
                ("x1", 6, "local", "continuous", None, "first state"),
                ("x2", 7, "local", "continuous", None, "second state"),
                (
                    "fail_at",
                    8,
                    "parameter",
                    "fixed",
                    Some(-1.0),
                    "fail the step at this time",
                ),
                (
                    "a",
                    9,
                    "calculatedParameter",
                    "fixed",
                    None,
                    "(1 - theta^2) sin(50 theta^2)",
                ),
                (
                    "crash_at",
                    10,
                    "parameter",
                    "fixed",
                    Some(-1.0),
                    "abort the process at this time",
                ),
                (
                    "fail_fatally",
                    11,
                    "parameter",
                    "fixed",
                    Some(0.0),
                    "fail with status Fatal",
                ),
            ],
            (vec![5], vec![]),
        ),
        Model::Pendulum => (
            "{twostage-pendulum-1}",
            format!("<ModelExchange modelIdentifier=\"{id}\"/>"),
            vec![
                ("k", 0, "parameter", "tunable", Some(1.0), "stiffness"),
                ("c", 1, "parameter", "fixed", Some(0.1), "damping"),
                ("u", 2, "input", "continuous", Some(0.0), "torque"),
                ("y", 3, "output", "continuous", None, "angle"),
                ("phi", 4, "local", "continuous", Some(0.5), "angle state"),
                ("omega", 5, "local", "continuous", Some(0.0), "rate state"),
                ("der(phi)", 6, "local", "continuous", None, ""),
                ("der(omega)", 7, "local", "continuous", None, ""),
                (
                    "kick_at",
                    8,
                    "parameter",
                    "fixed",
                    Some(-1.0),
                    "time of the kick",
                ),
            ],
            (vec![3], vec![(6, 4), (7, 5)]),
        ),
        Model::Integrator(interpolates) => (
            "{twostage-integrator-1}",
            format!(
                "<CoSimulation modelIdentifier=\"{id}\" canHandleVariableCommunicationStepSize=\"true\" canInterpolateInputs=\"{interpolates}\"/>"
            ),
            vec![
                ("gain", 0, "parameter", "fixed", Some(1.0), "gain"),
                ("u", 1, "input", "continuous", Some(0.0), "input"),
                ("y", 2, "output", "continuous", None, "integral"),
            ],
            (vec![2], vec![]),
        ),
    };
    let mut xml = String::new();
    let head = match version {
        FmiVersion::V2 => format!(
            "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"{id}\" guid=\"{token}\" numberOfEventIndicators=\"0\">"
        ),
        _ => format!(
            "<fmiModelDescription fmiVersion=\"3.0\" modelName=\"{id}\" instantiationToken=\"{token}\">"
        ),
    };
    xml.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    xml.push_str(&head);
    xml.push_str("\n  ");
    xml.push_str(&interface);
    if matches!(model, Model::Benchmark | Model::BenchmarkOnce) {
        // One doStep of 1 per sample, as the model file should say.
        xml.push_str("\n  <DefaultExperiment startTime=\"0\" stopTime=\"300\" stepSize=\"1\"/>");
    }
    xml.push_str("\n  <ModelVariables>\n");
    for (i, (name, vr, causality, variability, start, text)) in variables.iter().enumerate() {
        let start = start.map(|s| format!(" start=\"{s}\"")).unwrap_or_default();
        // Derivatives point at their state (FMI 2.0: 1-based index; 3.0: value reference).
        let derivative = structure.1.iter().find(|(d, _)| d == vr).map(|(_, s)| *s);
        match version {
            FmiVersion::V2 => {
                let derivative = derivative
                    .map(|s| {
                        format!(
                            " derivative=\"{}\"",
                            variables.iter().position(|v| v.1 == s).unwrap() + 1
                        )
                    })
                    .unwrap_or_default();
                xml.push_str(&format!(
                    "    <ScalarVariable name=\"{name}\" valueReference=\"{vr}\" causality=\"{causality}\" variability=\"{variability}\" description=\"{text}\"><Real{start}{derivative}/></ScalarVariable>\n"
                ));
            }
            _ => {
                let derivative = derivative
                    .map(|s| format!(" derivative=\"{s}\""))
                    .unwrap_or_default();
                xml.push_str(&format!(
                    "    <Float64 name=\"{name}\" valueReference=\"{vr}\" causality=\"{causality}\" variability=\"{variability}\" description=\"{text}\"{start}{derivative}/>\n"
                ));
            }
        }
        let _ = i;
    }
    xml.push_str("  </ModelVariables>\n  <ModelStructure>\n");
    let index = |vr: u32| variables.iter().position(|v| v.1 == vr).unwrap() + 1;
    match version {
        FmiVersion::V2 => {
            xml.push_str("    <Outputs>");
            for o in &structure.0 {
                xml.push_str(&format!("<Unknown index=\"{}\"/>", index(*o)));
            }
            xml.push_str("</Outputs>\n");
            if !structure.1.is_empty() {
                xml.push_str("    <Derivatives>");
                for (d, _) in &structure.1 {
                    xml.push_str(&format!("<Unknown index=\"{}\"/>", index(*d)));
                }
                xml.push_str("</Derivatives>\n");
            }
        }
        _ => {
            for o in &structure.0 {
                xml.push_str(&format!("    <Output valueReference=\"{o}\"/>\n"));
            }
            for (d, _) in &structure.1 {
                xml.push_str(&format!(
                    "    <ContinuousStateDerivative valueReference=\"{d}\"/>\n"
                ));
            }
        }
    }
    xml.push_str("  </ModelStructure>\n</fmiModelDescription>\n");
    xml
}

/// Zip the folder `root` into `fmu`.
pub fn zip_folder(root: &Path, fmu: &Path) {
    let file = std::fs::File::create(fmu).unwrap();
    let mut zip = zip::ZipWriter::new(file);
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let mut entries: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                stack.push(path);
            } else {
                let name = path
                    .strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/");
                zip.start_file(name, options).unwrap();
                zip.write_all(&std::fs::read(&path).unwrap()).unwrap();
            }
        }
    }
    zip.finish().unwrap();
}

/// Build `model` as an FMI `version` FMU; `edit` may change the unpacked
/// folder (the description, the binaries) before it is zipped.
pub fn build_with(model: Model, version: FmiVersion, edit: impl FnOnce(&Path)) -> TestFmu {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("unpacked");
    let binary = root
        .join("binaries")
        .join(platform_folder(version))
        .join(format!(
            "{}{}",
            identifier(model),
            std::env::consts::DLL_SUFFIX
        ));
    compile(model, version, &binary);
    std::fs::create_dir_all(root.join("resources")).unwrap();
    std::fs::write(
        root.join("modelDescription.xml"),
        description(model, version),
    )
    .unwrap();
    edit(&root);
    let path = dir.path().join(format!("{}.fmu", identifier(model)));
    zip_folder(&root, &path);
    TestFmu { path, _dir: dir }
}

/// Build `model` as an FMI `version` FMU.
pub fn build(model: Model, version: FmiVersion) -> TestFmu {
    build_with(model, version, |_| {})
}

/// The pendulum of tests/fmus/pendulum.c in Rust, with the input held
/// over each sample, as the FMU simulator holds it.
pub struct Pendulum {
    pub k: f64,
    pub c: f64,
    pub u: f64,
}

impl OdeSystem for Pendulum {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, x: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = -self.k * x[0].sin() - self.c * x[1] + self.u;
    }
}

pub const PENDULUM_STEP: f64 = 0.05;
pub const PENDULUM_DIVISOR: usize = 4;

/// y = phi at every sample, from phi = 0.5, omega = 0, with RK4 steps of
/// PENDULUM_STEP / PENDULUM_DIVISOR, and a kick of +1 to omega at step
/// `kick_step` if given.
pub fn pendulum_in_rust(k: f64, c: f64, u: &[f64], kick_step: Option<usize>) -> Vec<f64> {
    let mut x = [0.5, 0.0];
    let mut rk4 = Rk4::new(2);
    let h = PENDULUM_STEP / PENDULUM_DIVISOR as f64;
    let mut y = Vec::with_capacity(u.len());
    for (k_sample, &u_k) in u.iter().enumerate() {
        y.push(x[0]);
        if k_sample + 1 == u.len() {
            break;
        }
        let system = Pendulum { k, c, u: u_k };
        for s in 0..PENDULUM_DIVISOR {
            let step = k_sample * PENDULUM_DIVISOR + s;
            rk4.step(&system, step as f64 * h, h, &mut x);
            if kick_step == Some(step + 1) {
                x[1] += 1.0;
            }
        }
    }
    y
}
