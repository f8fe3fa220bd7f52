//! Writing the corpus: the repository's own valid files of each reader.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use twostage::TwoStage;
use twostage::models::{Benchmark, PacejkaCar, Simulator, experiment_rng};
use twostage::sources::TEMPLATE;

use super::Reader;
use super::targets::{ANSWER_SAMPLES, NPY_FILES, npy_chart, shard_sets};

/// A file of a set, after the byte that says which of the set it is.
fn selected(which: usize, bytes: &[u8]) -> Vec<u8> {
    let mut input = vec![which as u8];
    input.extend_from_slice(bytes);
    input
}

/// Answers of a simulator to experiment 0 of a one-input, one-output
/// model: a record as Python prints it, one with exponents and CRLF line
/// ends, and a failure.
fn protocol_answers() -> Result<Vec<(String, Vec<u8>)>> {
    let model = Benchmark::builder().n_samples(ANSWER_SAMPLES).build()?;
    let mut record = model.spec().new_record();
    model.simulate(&[0.4], &mut experiment_rng(2, 0), &mut record)?;
    let (mut plain, mut exponents) = (String::from("record 0\n"), String::from("record 0\r\n"));
    for (u, y) in record.input(0).iter().zip(record.output(0)) {
        plain.push_str(&format!("{u} {y}\n"));
        exponents.push_str(&format!("{u:e}\t{y:E}\r\n"));
    }
    Ok(vec![
        (
            "error.txt".to_string(),
            b"error 0 the plant refused theta 0.4\n".to_vec(),
        ),
        ("exponents.txt".to_string(), exponents.into_bytes()),
        ("plain.txt".to_string(), plain.into_bytes()),
    ])
}

/// An FMI 2.0 co-simulation description: parameters, an input, an
/// output, a default experiment.
const FMI2_DESCRIPTION: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="gain" guid="{twostage-fuzz-1}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="gain" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="300" stepSize="1"/>
  <ModelVariables>
    <ScalarVariable name="k" valueReference="0" causality="parameter" variability="fixed"><Real start="1.5" unit="1/s"/></ScalarVariable>
    <ScalarVariable name="u" valueReference="1" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="2" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="x" valueReference="3" causality="local" variability="continuous"><Real start="0.5"/></ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="4" causality="local" variability="continuous"><Real derivative="4"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="3"/></Outputs>
    <Derivatives><Unknown index="5"/></Derivatives>
  </ModelStructure>
</fmiModelDescription>
"#;

/// An FMI 3.0 description of both interfaces: units, types, arrays,
/// states, an input and an output.
const FMI3_DESCRIPTION: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="mass" instantiationToken="{twostage-fuzz-3}">
  <CoSimulation modelIdentifier="mass" canHandleVariableCommunicationStepSize="true"/>
  <ModelExchange modelIdentifier="mass"/>
  <UnitDefinitions><Unit name="m"/></UnitDefinitions>
  <TypeDefinitions><Float64Type name="Position" unit="m"/></TypeDefinitions>
  <DefaultExperiment startTime="0" stopTime="20" stepSize="0.05"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="c" valueReference="1" causality="parameter" variability="fixed" start="0.4"/>
    <Float64 name="k" valueReference="2" causality="parameter" variability="tunable" start="2"/>
    <Float64 name="force" valueReference="3" causality="input" variability="continuous" start="0"/>
    <Float64 name="x" valueReference="4" declaredType="Position" start="0.1"/>
    <Float64 name="v" valueReference="5" start="0"/>
    <Float64 name="der(x)" valueReference="6" derivative="4"/>
    <Float64 name="der(v)" valueReference="7" derivative="5"/>
    <Float64 name="position" valueReference="8" causality="output" variability="continuous"/>
    <Int32 name="mode" valueReference="9" causality="parameter" variability="fixed" start="1"/>
    <Float64 name="gains" valueReference="10" causality="parameter" variability="fixed" start="1 2 3">
      <Dimension start="3"/>
    </Float64>
  </ModelVariables>
  <ModelStructure>
    <Output valueReference="8"/>
    <ContinuousStateDerivative valueReference="6"/>
    <ContinuousStateDerivative valueReference="7"/>
    <InitialUnknown valueReference="8"/>
  </ModelStructure>
</fmiModelDescription>
"#;

/// An FMU archive of `description`, a stand-in binary at `binary` (never
/// loaded: the fuzzer reads archives, it does not run them) and a
/// resource.
fn fmu(description: &str, binary: &str) -> Result<Vec<u8>> {
    use std::io::Write;
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in [
        ("modelDescription.xml", description.as_bytes()),
        (binary, b"\x7fELF not a library".as_slice()),
        ("resources/table.txt", b"0 1\n1 2\n".as_slice()),
    ] {
        writer.start_file(name, options)?;
        writer.write_all(bytes)?;
    }
    Ok(writer.finish()?.into_inner())
}

/// Fill every reader's corpus folder from the repository's files and a few
/// small estimators trained here (deterministic: the same files each time).
pub(crate) fn write() -> Result<()> {
    for reader in Reader::ALL {
        let dir = reader.corpus_dir();
        fs::create_dir_all(&dir).with_context(|| format!("making {}", dir.display()))?;
        let files = match reader {
            Reader::EstimatorFile => estimators()?
                .into_iter()
                .map(|(name, e)| Ok((format!("{name}.tsest"), e.to_bytes()?)))
                .collect::<Result<Vec<_>>>()?,
            Reader::RuntimeBlob => estimators()?
                .into_iter()
                .map(|(name, e)| Ok((format!("{name}.tsrt"), e.to_runtime()?)))
                .collect::<Result<Vec<_>>>()?,
            Reader::ModelFile => model_files()?,
            Reader::CsvRows => csv_files()?,
            Reader::NpyChart => NPY_FILES
                .iter()
                .zip(npy_chart())
                .enumerate()
                .map(|(k, (name, bytes))| (format!("{k}-{name}"), selected(k, bytes)))
                .collect(),
            Reader::ShardFile => shard_sets()
                .iter()
                .zip(["raw", "compressed"])
                .enumerate()
                .flat_map(|(set, (files, kind))| {
                    files.iter().enumerate().map(move |(slot, bytes)| {
                        (
                            format!("{kind}-{slot}.tsshard"),
                            selected(slot | (set << 1), bytes),
                        )
                    })
                })
                .collect(),
            Reader::ProtocolAnswer => protocol_answers()?,
            Reader::FmuDescription => vec![
                ("fmi2.xml".to_string(), FMI2_DESCRIPTION.as_bytes().to_vec()),
                ("fmi3.xml".to_string(), FMI3_DESCRIPTION.as_bytes().to_vec()),
            ],
            Reader::FmuArchive => vec![
                (
                    "fmi2.fmu".to_string(),
                    fmu(FMI2_DESCRIPTION, "binaries/linux64/gain.so")?,
                ),
                (
                    "fmi3.fmu".to_string(),
                    fmu(FMI3_DESCRIPTION, "binaries/x86_64-linux/osc.so")?,
                ),
            ],
        };
        for (name, bytes) in files {
            fs::write(dir.join(&name), bytes).with_context(|| format!("writing {name}"))?;
        }
    }
    Ok(())
}

/// Small estimators of every kind a file holds: a network, pieces, a
/// linear map, the car's two parameters, a posterior, a parameter held.
fn estimators() -> Result<Vec<(&'static str, twostage::Estimator)>> {
    let benchmark = Benchmark::builder().n_samples(120).build()?;
    let car = PacejkaCar::builder().n_samples(100).build()?;
    let train = |model: &dyn Simulator, regressor: &str| -> Result<twostage::Estimator> {
        Ok(TwoStage::builder(model)
            .compressor(twostage::compress::Arx::new(2, 2)?)
            .regressor(regressor.parse()?)
            .simulations(200)
            .validation(0)
            .calibration(100)
            .seed(3)
            .train()?)
    };
    // A posterior: the estimator file's density and the blob's section
    // that the runtime draws from.
    let with_posterior = TwoStage::builder(&car)
        .compressor(twostage::compress::Arx::new(2, 2)?)
        .regressor("mlp:3".parse()?)
        .posterior(twostage::fit::MixtureDensity::new(
            twostage::fit::MlpParams::new(&[4])?.check()?,
            2,
        )?)
        .simulations(200)
        .validation(0)
        .calibration(100)
        .seed(3)
        .train()?;
    // A parameter held at a value: format 10's list after the posterior's
    // empty slot.
    let fixed = twostage::models::FixedValues::parse(&["pK2=-1.05"])?;
    let held = twostage::models::WithFixed::new(&car, &fixed)?;
    let with_fixed = train(&held, "mlp:3")?.with_fixed(fixed);
    Ok(vec![
        ("car-fixed", with_fixed),
        ("car-posterior", with_posterior),
        ("benchmark-mlp", train(&benchmark, "mlp:4")?),
        ("benchmark-piecewise", train(&benchmark, "piecewise:2,3")?),
        ("benchmark-linear", train(&benchmark, "linear")?),
        ("car-mlp", train(&car, "mlp:3")?),
    ])
}

/// The example model files and the template.
fn model_files() -> Result<Vec<(String, Vec<u8>)>> {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples");
    let mut files = vec![("template.toml".to_string(), TEMPLATE.as_bytes().to_vec())];
    for folder in fs::read_dir(&examples)? {
        let folder = folder?.path();
        if !folder.is_dir() {
            continue;
        }
        for file in fs::read_dir(&folder)? {
            let file = file?.path();
            if file.extension().is_some_and(|e| e == "toml") {
                let name = file
                    .file_name()
                    .and_then(|n| n.to_str())
                    .unwrap_or("model.toml");
                files.push((name.to_string(), fs::read(&file)?));
            }
        }
    }
    files.sort();
    Ok(files)
}

/// Records in the long format, a chart's rows, and a quoted oddity.
fn csv_files() -> Result<Vec<(String, Vec<u8>)>> {
    let model = Benchmark::builder().n_samples(40).build()?;
    let mut long = String::from("record,u,y\n");
    let mut chart = String::from("theta,u,y\n");
    for (r, theta) in [0.2, -0.4].into_iter().enumerate() {
        let mut record = model.spec().new_record();
        model.simulate(&[theta], &mut experiment_rng(5, r as u64), &mut record)?;
        for (u, y) in record.input(0).iter().zip(record.output(0)) {
            long.push_str(&format!("{r},{u},{y}\n"));
            chart.push_str(&format!("{theta},{u:e},{y:e}\n"));
        }
    }
    let quoted = "\"name, with comma\",\"x\"\n\"a \"\"b\"\"\",1.5\n  7 , -2e-3 \n".to_string();
    Ok(vec![
        ("chart.csv".to_string(), chart.into_bytes()),
        ("long.csv".to_string(), long.into_bytes()),
        ("quoted.csv".to_string(), quoted.into_bytes()),
    ])
}
