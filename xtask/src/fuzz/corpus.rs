//! Writing the corpus: the repository's own valid files of each reader.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use twostage::TwoStage;
use twostage::models::{Benchmark, PacejkaCar, Simulator, experiment_rng};
use twostage::sources::TEMPLATE;

use super::Reader;

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
        };
        for (name, bytes) in files {
            fs::write(dir.join(&name), bytes).with_context(|| format!("writing {name}"))?;
        }
    }
    Ok(())
}

/// Small estimators of every kind a file holds: a network, pieces, a
/// linear map, and the car's two parameters.
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
    Ok(vec![
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
