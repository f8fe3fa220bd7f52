//! Charts simulated elsewhere, read from CSV files: the same estimator as
//! when simulating the same chart, held-out parts when there is no
//! simulator, and every file problem named by file and line.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use common::write_chart;
use std::path::{Path, PathBuf};

use twostage::models::{Benchmark, IoData, Simulator, run_experiment};
use twostage::{ChartFiles, RecordSource, TwoStage};

fn model() -> Benchmark {
    Benchmark::builder().n_samples(200).build().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

#[test]
fn a_chart_from_files_trains_the_same_stages_as_simulating_it() {
    let model = model();
    let (train, check) = (scratch("chart-same-train"), scratch("chart-same-check"));
    write_chart(&model, &train, 300, 7);
    write_chart(&model, &check, 120, 8);
    let builder = || {
        TwoStage::builder(&model)
            .preset(twostage::paper_benchmark())
            .simulations(300)
            .seed(7)
    };
    let spec = model.spec();
    let (chart, other) = (
        ChartFiles::open(&train, spec).unwrap(),
        ChartFiles::open(&check, spec).unwrap(),
    );
    let from_files = builder()
        .records(RecordSource::Files {
            training: &chart,
            calibration: Some(&other),
            validation: Some(&other),
        })
        .train()
        .unwrap();
    let simulated = builder().validation(0).calibration(0).train().unwrap();
    // Stage 1 and stage 2 are the same bits: the chart is the design's.
    assert_eq!(from_files.compressor(), simulated.compressor());
    assert!(
        from_files.regressor() == simulated.regressor(),
        "the fitted networks differ"
    );
    let report = from_files.validation().unwrap();
    assert_eq!(report.total.r, 120);
    assert!(report.parameters[0].rmse < 0.15, "{report}");
    assert!(from_files.training().sampling.contains("chart-same-check"));
}

#[test]
fn without_other_charts_the_checks_are_held_out_at_random_and_reproducibly() {
    let model = model();
    let dir = scratch("chart-held-out");
    write_chart(&model, &dir, 260, 3);
    let chart = ChartFiles::open(&dir, model.spec()).unwrap();
    let train = || {
        TwoStage::builder(&model)
            .preset(twostage::paper_benchmark())
            .validation(60)
            .calibration(50)
            .seed(2)
            .records(RecordSource::Files {
                training: &chart,
                calibration: None,
                validation: None,
            })
            .train()
            .unwrap()
    };
    let a = train();
    assert_eq!(a.training().simulations, 150);
    assert_eq!(a.validation().unwrap().total.r, 60);
    assert!(a.training().sampling.contains("60 records held out"));
    assert_eq!(a.to_bytes().unwrap(), train().to_bytes().unwrap());
    let e = TwoStage::builder(&model)
        .validation(200)
        .calibration(100)
        .records(RecordSource::Files {
            training: &chart,
            calibration: None,
            validation: None,
        })
        .train()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("has 260 records: at least 10 must be left"),
        "{e}"
    );
}

#[test]
fn every_file_problem_names_its_file_and_line() {
    let model = model();
    let spec = model.spec();
    let dir = scratch("chart-problems");
    let cases: &[(&str, &str, &str, Option<usize>, &str)] = &[
        // (file, replace, with, line, message)
        (
            "truth.csv",
            "experiment,theta",
            "experiment,beta",
            Some(1),
            "expected 'experiment,theta'",
        ),
        (
            "truth.csv",
            "\n1,",
            "\n0,",
            Some(3),
            "experiment '0' again (first on line 2)",
        ),
        (
            "data.csv",
            "experiment,u,y",
            "experiment,u",
            Some(1),
            "or u,y",
        ),
        // What the header lacks and has too many of, as a record file's
        // reader says it.
        (
            "data.csv",
            "experiment,u,y",
            "experiment,u,z",
            Some(1),
            "missing y; extra z (not a signal of the model: remove the column)",
        ),
        (
            "data.csv",
            "experiment,u,y",
            "u,y,experiment",
            Some(1),
            "the first column must be experiment",
        ),
        (
            "data.csv",
            "\n2,",
            "\n2,nan,",
            Some(2),
            "values, the header has 3",
        ),
        (
            "data.csv",
            "\n1,",
            "\n7,",
            Some(202),
            "experiment '7' is not in truth.csv",
        ),
    ];
    for (file, from, to, line, text) in cases {
        write_chart(&model, &dir, 3, 1);
        let path = dir.join(file);
        let body = std::fs::read_to_string(&path).unwrap();
        assert!(body.contains(from), "{from}");
        std::fs::write(&path, body.replacen(from, to, 1)).unwrap();
        let e = ChartFiles::open(&dir, spec)
            .and_then(|chart| chart.for_each_record(spec, |_, _| Ok(())))
            .unwrap_err();
        match &e {
            twostage::sources::Error::ChartFile {
                file: f,
                line: l,
                message,
            } => {
                assert!(f.ends_with(file), "{e}");
                assert_eq!(l, line, "{from} -> {to}: {e}");
                assert!(message.contains(text), "{from} -> {to}: {e}");
            }
            other => panic!("{other}"),
        }
    }
    // A value that is not a number names its column; a short record and a
    // missing experiment are named too.
    write_chart(&model, &dir, 3, 1);
    let data = std::fs::read_to_string(dir.join("data.csv")).unwrap();
    let mut lines: Vec<String> = data.lines().map(str::to_string).collect();
    lines[5] = "2,0.5,abc".into();
    std::fs::write(dir.join("data.csv"), lines.join("\n")).unwrap();
    let chart = ChartFiles::open(&dir, spec).unwrap();
    let e = chart
        .for_each_record(spec, |_, _| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 6: column y: 'abc' is not a finite number"),
        "{e}"
    );
    lines.remove(5);
    std::fs::write(dir.join("data.csv"), lines.join("\n")).unwrap();
    let e = chart
        .for_each_record(spec, |_, _| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("experiment '2' (from line 2) has 199 samples"),
        "{e}"
    );
    let without_last: Vec<&str> = data.lines().filter(|l| !l.starts_with("0,")).collect();
    std::fs::write(dir.join("data.csv"), without_last.join("\n")).unwrap();
    let e = chart
        .for_each_record(spec, |_, _| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("1 experiment(s) of truth.csv have no rows, the first '0'"),
        "{e}"
    );
    // Rows of one experiment must stay together: experiment 2 again at the end.
    let all: Vec<&str> = data.lines().collect();
    let mut split = all.clone();
    split.extend_from_slice(&all[1..201]);
    std::fs::write(dir.join("data.csv"), split.join("\n")).unwrap();
    let e = chart
        .for_each_record(spec, |_, _| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("resumes after other experiments"), "{e}");
}

/// `values` as a float64 .npy file of `shape`.
fn write_npy(path: &Path, shape: &[u64], values: impl IntoIterator<Item = f64>) {
    use npyz::WriterBuilder;
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(file)
        .begin_nd()
        .unwrap();
    writer.extend(values).unwrap();
    writer.finish().unwrap();
}

/// The chart of `write_chart` as NumPy arrays: theta [m, 1], inputs and
/// outputs [m, N, 1].
fn write_numpy_chart(dir: &Path, m: usize, seed: u64) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let model = model();
    let design = model.prior().design(m, seed).unwrap();
    let (mut thetas, mut inputs, mut outputs) = (Vec::new(), Vec::new(), Vec::new());
    let (mut theta, mut record) = ([0.0], IoData::default());
    for i in 0..m {
        run_experiment(&model, &design, i, &mut theta, &mut record).unwrap();
        thetas.push(theta[0]);
        inputs.extend_from_slice(record.input(0));
        outputs.extend_from_slice(record.output(0));
    }
    let n = model.spec().n_samples() as u64;
    write_npy(&dir.join("theta.npy"), &[m as u64, 1], thetas);
    write_npy(&dir.join("inputs.npy"), &[m as u64, n, 1], inputs);
    write_npy(&dir.join("outputs.npy"), &[m as u64, n, 1], outputs);
}

#[test]
fn a_numpy_chart_trains_the_same_networks_as_the_csv_one() {
    let model = model();
    let (csv, npy) = (scratch("chart-npy-csv"), scratch("chart-npy-npy"));
    write_chart(&model, &csv, 240, 9);
    write_numpy_chart(&npy, 240, 9);
    let train = |dir: &Path| {
        let chart = ChartFiles::open(dir, model.spec()).unwrap();
        TwoStage::builder(&model)
            .preset(twostage::paper_benchmark())
            .validation(40)
            .calibration(40)
            .seed(1)
            .records(RecordSource::Files {
                training: &chart,
                calibration: None,
                validation: None,
            })
            .train()
            .unwrap()
    };
    let (from_csv, from_npy) = (train(&csv), train(&npy));
    assert!(
        from_csv.regressor() == from_npy.regressor(),
        "the fitted networks differ"
    );
    assert!(from_csv.validation() == from_npy.validation());
    // Wrong shapes and values are named by file.
    write_npy(
        &npy.join("outputs.npy"),
        &[240, 199, 1],
        vec![0.0; 240 * 199],
    );
    let e = ChartFiles::open(&npy, model.spec())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("outputs.npy: shape [240, 199, 1]: expected [240, 200, 1]"),
        "{e}"
    );
    let mut values = vec![0.5; 240 * 200];
    values[200 * 7 + 3] = f64::NAN;
    write_npy(&npy.join("outputs.npy"), &[240, 200, 1], values);
    let chart = ChartFiles::open(&npy, model.spec()).unwrap();
    let e = chart
        .for_each_record(model.spec(), |_, _| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("outputs.npy: [7, 3, 0] = NaN is not a finite number"),
        "{e}"
    );
    write_npy(&npy.join("theta.npy"), &[240, 2], vec![0.1; 480]);
    let e = ChartFiles::open(&npy, model.spec())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("theta.npy: shape [240, 2]: expected [m, 1]"),
        "{e}"
    );
    std::fs::write(npy.join("theta.npy"), b"not numpy").unwrap();
    let e = ChartFiles::open(&npy, model.spec())
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a NumPy .npy file"), "{e}");
    // A float32 array of the right size is told what to save, not that it
    // was cut short.
    let float32 = {
        use npyz::WriterBuilder;
        let path = npy.join("theta.npy");
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[240, 1])
            .writer(file)
            .begin_nd()
            .unwrap();
        writer.extend(vec![0.1f32; 240]).unwrap();
        writer.finish().unwrap();
        ChartFiles::open(&npy, model.spec())
            .unwrap_err()
            .to_string()
    };
    assert!(float32.contains("save float64 arrays"), "{float32}");
    write_npy(&npy.join("theta.npy"), &[240, 1], vec![0.1; 240]);
    ChartFiles::open(&npy, model.spec()).unwrap();
}

/// Headers the fuzzer made (`cargo xtask fuzz --reader npy-chart`): a
/// length word of 4 GB, which the NumPy reader allocated until the
/// process aborted; a shape nested in itself hundreds deep and
/// dictionaries nested in the header, which it parsed for minutes; a
/// shape whose values the file does not hold.
#[test]
fn forged_numpy_headers_are_refused_before_they_are_believed() {
    let model = model();
    let dir = scratch("chart-npy-forged");
    write_numpy_chart(&dir, 3, 2);
    let valid = std::fs::read(dir.join("theta.npy")).unwrap();
    let header = |version: u8, text: &str| -> Vec<u8> {
        let mut bytes = b"\x93NUMPY".to_vec();
        bytes.extend_from_slice(&[version, 0]);
        match version {
            1 => bytes.extend_from_slice(&(text.len() as u16).to_le_bytes()),
            _ => bytes.extend_from_slice(&(text.len() as u32).to_le_bytes()),
        }
        bytes.extend_from_slice(text.as_bytes());
        bytes
    };
    let refused = |bytes: &[u8], said: &str| {
        std::fs::write(dir.join("theta.npy"), bytes).unwrap();
        let e = ChartFiles::open(&dir, model.spec())
            .unwrap_err()
            .to_string();
        assert!(e.contains("theta.npy") && e.contains(said), "{e}");
    };
    // A version-3 length word of 4,286,251,126 bytes, as found.
    let mut claiming = b"\x93NUMPY\x03\x00\x76\x00\x7b\xff".to_vec();
    claiming.extend_from_slice(&valid[10..]);
    refused(
        &claiming,
        "its header claims 4286251126 bytes, where NumPy writes and reads at most 10000",
    );
    // A shape nested in itself, then dictionaries nested in the header,
    // as the fuzzer found them.
    let nested = [
        ("(3,".repeat(300), "3", ")".repeat(300), "'shape': "),
        (
            "{'a': ".repeat(40),
            "1",
            "}".repeat(40),
            "'shape': (3, 1), 'x': ",
        ),
    ];
    for (open, inside, close, key) in nested {
        let text =
            format!("{{'descr': '<f8', 'fortran_order': False, {key}{open}{inside}{close}, }}\n");
        refused(&header(1, &text), "nests brackets deeper than a dictionary");
    }
    let mut short = header(
        1,
        "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 1), }\n",
    );
    short.extend_from_slice(&0.5f64.to_le_bytes());
    refused(
        &short,
        "its shape [1000000000000, 1] declares 8.0 TB of values, the file holds",
    );
}
