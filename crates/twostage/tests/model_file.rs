//! Model files: what they build, and every mistake named by line and key.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use twostage::models::{Benchmark, Marginal, NoiseFree, Simulator, experiment_rng};
use twostage::{MODEL_FILE_TEMPLATE, ModelFile, ModelSource};

const GOOD: &str = r#"[model]
name = "quiet-benchmark"
[source]
builtin = "benchmark"
[[parameter]]
name = "a"
prior = { dist = "normal", mu = 0.1, sigma = 0.2 }
[signals]
inputs = ["force"]
outputs = ["position"]
samples = 300
[noise]
model = false
output_sd = 0.5
"#;

/// The noise a file of GOOD's model adds: its records at 0.3 minus the
/// noiseless benchmark's on the same streams (`runs` experiments of
/// `seed`), one after another.
fn added_noise(file: &ModelFile, runs: u64, seed: u64) -> Vec<f64> {
    let simulator = file.simulator().unwrap();
    let noiseless = NoiseFree::new(Box::new(
        Benchmark::builder().n_samples(300).build().unwrap(),
    ))
    .unwrap();
    let spec = file.spec();
    let (mut noisy, mut clean) = (spec.new_record(), spec.new_record());
    let mut added = Vec::new();
    for i in 0..runs {
        simulator
            .simulate(&[0.3], &mut experiment_rng(seed, i), &mut noisy)
            .unwrap();
        noiseless
            .simulate(&[0.3], &mut experiment_rng(seed, i), &mut clean)
            .unwrap();
        assert_eq!(noisy.n_samples(), 300);
        assert!(noisy.input(0) == clean.input(0), "the same input stream");
        added.extend(
            noisy
                .output(0)
                .iter()
                .zip(clean.output(0))
                .map(|(a, b)| a - b),
        );
    }
    added
}

/// `output_ar` colours the file's noise: the difference from the
/// noise-free model is AR(1) of that coefficient with the sd of
/// `output_sd`, measured over many samples.
#[test]
fn the_files_output_noise_can_be_coloured() {
    let file = ModelFile::parse(
        &GOOD.replace("output_sd = 0.5", "output_sd = 0.5\noutput_ar = 0.9"),
        "ar.toml",
    )
    .unwrap();
    // One series per record: no lag across records.
    let added = added_noise(&file, 200, 6);
    let (mut square, mut lagged) = (0.0, 0.0);
    for e in added.chunks(300) {
        square += e.iter().map(|v| v * v).sum::<f64>();
        lagged += e.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
    }
    let count = added.len() as f64;
    let (variance, rho) = (square / count, lagged / square);
    assert!(
        (variance.sqrt() - 0.5).abs() < 0.03,
        "sd {}",
        variance.sqrt()
    );
    assert!((rho - 0.9).abs() < 0.02, "lag-one correlation {rho}");
    // Noise-free runs leave it out: the model's own response.
    let simulator = file.simulator().unwrap();
    let noiseless = NoiseFree::new(Box::new(
        Benchmark::builder().n_samples(300).build().unwrap(),
    ))
    .unwrap();
    let mut given = file.spec().new_record();
    noiseless
        .simulate(&[0.3], &mut experiment_rng(6, 0), &mut given)
        .unwrap();
    let quiet = twostage::models::Conditions {
        noiseless: true,
        input: Some(&given),
    };
    let (mut ours, mut reference) = (file.spec().new_record(), file.spec().new_record());
    simulator
        .simulate_under(&[0.3], &mut experiment_rng(6, 0), quiet, &mut ours)
        .unwrap();
    noiseless
        .simulate_under(&[0.3], &mut experiment_rng(6, 0), quiet, &mut reference)
        .unwrap();
    assert_eq!(ours.output(0), reference.output(0));
}

#[test]
fn a_built_in_source_takes_the_files_names_prior_length_and_noise() {
    let file = ModelFile::parse(GOOD, "good.toml").unwrap();
    let spec = file.spec();
    assert_eq!(file.name(), "quiet-benchmark");
    assert_eq!(spec.param_names(), ["a"]);
    assert_eq!(spec.input_names(), ["force"]);
    assert_eq!(spec.output_names(), ["position"]);
    assert_eq!(spec.n_samples(), 300);
    assert_eq!(
        spec.prior().marginals(),
        [Marginal::Normal {
            mu: 0.1,
            sigma: 0.2
        }]
    );
    assert!(matches!(file.source(), ModelSource::Builtin { .. }));
    // The file's noise is the only noise: the difference from the noiseless
    // benchmark (same stream, same input) is white with sd 0.5.
    let added = added_noise(&file, 20, 4);
    let sum_sq: f64 = added.iter().map(|e| e * e).sum();
    let runs = 20;
    // 6000 draws: the sample sd is within 3% of 0.5 with overwhelming odds.
    let sd = (sum_sq / (runs as f64 * 300.0)).sqrt();
    assert!((sd / 0.5 - 1.0).abs() < 0.03, "noise sd {sd}");
}

#[test]
fn leaving_out_the_parameters_keeps_the_built_in_priors_and_presets() {
    let file = ModelFile::parse(
        "[model]\nname = \"car\"\n[source]\nbuiltin = \"pacejka\"\n",
        "car.toml",
    )
    .unwrap();
    let car = twostage::models::PacejkaCar::new();
    assert_eq!(file.spec().prior(), car.prior());
    assert_eq!(file.spec().param_names(), car.param_names());
    // The model named by its file: the built-in presets come along.
    let named = twostage::NamedModel::File(Box::new(file));
    assert_eq!(
        named.preset(Some("paper")).unwrap(),
        twostage::paper_pacejka(),
        "the built-in presets come along"
    );
    assert_eq!(named.preset(None).unwrap(), twostage::paper_pacejka());
    let e = named.preset(Some("fast")).unwrap_err().to_string();
    assert!(
        e.contains("preset 'fast' is not available for car: it has paper"),
        "{e}"
    );
}

#[test]
fn a_file_without_a_source_describes_charts_and_cannot_simulate() {
    let text = r#"[model]
name = "sir"
[[parameter]]
name = "beta"
prior = { dist = "lognormal", mu = -0.916, sigma = 0.5 }
[[parameter]]
name = "gamma"
prior = { dist = "uniform", low = 0.05, high = 0.3 }
[signals]
inputs = []
outputs = ["I"]
samples = 10
"#;
    let file = ModelFile::parse(text, "sir.toml").unwrap();
    assert_eq!(file.source(), &ModelSource::ChartsOnly);
    assert_eq!(file.spec().input_names().len(), 0);
    assert_eq!(file.spec().n_samples(), 10);
    let e = file.simulator().map(|_| ()).unwrap_err();
    assert!(
        matches!(e, twostage::sources::Error::ModelFile { ref key, .. } if key == "source"),
        "{e}"
    );
}

/// A file without a source takes one from the caller (the Python
/// package's functions): the file's noise on top of the source's records,
/// and a source of another shape refused.
#[test]
fn a_file_without_a_source_simulates_with_a_given_one() {
    let text = r#"[model]
name = "given"
[[parameter]]
name = "theta"
prior = { dist = "uniform", low = -0.9, high = 0.9 }
[signals]
inputs = ["u"]
outputs = ["y"]
samples = 1000
[noise]
output_sd = 0.5
"#;
    let file = ModelFile::parse(text, "given.toml").unwrap();
    let sim = file.simulator_with(Box::new(Benchmark::new())).unwrap();
    let (mut given, mut plain) = (sim.spec().new_record(), sim.spec().new_record());
    sim.simulate(&[0.3], &mut experiment_rng(2, 5), &mut given)
        .unwrap();
    Benchmark::new()
        .simulate(&[0.3], &mut experiment_rng(2, 5), &mut plain)
        .unwrap();
    assert_eq!(given.input(0), plain.input(0));
    // The file's noise, sd 0.5, drawn after the source's own.
    let added: Vec<f64> = given
        .output(0)
        .iter()
        .zip(plain.output(0))
        .map(|(a, b)| a - b)
        .collect();
    let sd = (added.iter().map(|d| d * d).sum::<f64>() / added.len() as f64).sqrt();
    assert!((sd - 0.5).abs() < 0.05, "{sd}");
    let short = Benchmark::builder().n_samples(300).build().unwrap();
    let e = file
        .simulator_with(Box::new(short))
        .map(|_| ())
        .unwrap_err();
    assert!(e.to_string().contains("300 samples"), "{e}");
    let own = ModelFile::parse(GOOD, "good.toml").unwrap();
    let e = own
        .simulator_with(Box::new(Benchmark::new()))
        .map(|_| ())
        .unwrap_err();
    assert!(e.to_string().contains("its own [source]"), "{e}");
}

#[test]
fn the_template_parses_and_simulates() {
    let file = ModelFile::parse(MODEL_FILE_TEMPLATE, "template.toml").unwrap();
    let sim = file.simulator().unwrap();
    let mut record = sim.spec().new_record();
    sim.simulate(&[0.2], &mut experiment_rng(1, 0), &mut record)
        .unwrap();
    assert_eq!(record.n_samples(), 500);
    assert_eq!(file.preset_names().next(), Some("default"));
}

/// Replace `from` by `to` in the good file: each mistake must be named by
/// its line and key.
#[test]
fn every_mistake_names_its_line_and_key() {
    let cases: &[(&str, &str, Option<usize>, &str, &str)] = &[
        // (replace, with, line, key, text in the message)
        (
            "[source]",
            "[sourse]",
            Some(3),
            "",
            "unknown field `sourse`",
        ),
        (
            "name = \"a\"",
            "nam = \"a\"",
            Some(6),
            "",
            "unknown field `nam`",
        ),
        (
            "sigma = 0.2",
            "sigma = -0.2",
            Some(7),
            "parameter.prior",
            "sigma finite and > 0",
        ),
        (
            "sigma = 0.2",
            "sigma = \"wide\"",
            Some(7),
            "parameter.prior.sigma",
            "invalid type",
        ),
        (
            "dist = \"normal\"",
            "dist = \"gauss\"",
            Some(7),
            "parameter.prior.dist",
            "unknown distribution 'gauss'",
        ),
        (
            "mu = 0.1, sigma = 0.2",
            "mu = 0.1, sigma = 0.2, low = 0",
            Some(7),
            "parameter.prior.low",
            "takes exactly mu, sigma",
        ),
        (
            "mu = 0.1, sigma = 0.2",
            "mu = 0.1",
            Some(7),
            "parameter.prior.sigma",
            "takes exactly mu, sigma",
        ),
        (
            "builtin = \"benchmark\"",
            "builtin = \"tractor\"",
            Some(4),
            "source.builtin",
            "tractor",
        ),
        (
            "samples = 300",
            "samples = 0",
            Some(11),
            "signals.samples",
            "at least 1",
        ),
        (
            "samples = 300",
            "samples = 1000000000000",
            Some(11),
            "signals.samples",
            "would take 16.0 TB for one record, which is held whole in memory (by each \
             thread at once): at most 67108864 samples fit the 1.1 GB",
        ),
        (
            "samples = 300",
            "samples = 300\nsample_time = 0.5",
            Some(12),
            "signals.sample_time",
            "samples every 1",
        ),
        (
            "outputs = [\"position\"]",
            "outputs = [\"p\", \"q\"]",
            Some(10),
            "signals.outputs",
            "rename them one for one",
        ),
        (
            "output_sd = 0.5",
            "output_sd = [0.5, 0.1]",
            Some(14),
            "noise.output_sd",
            "a list of 1",
        ),
        (
            "output_sd = 0.5",
            "output_sd = -1.0",
            Some(14),
            "noise.output_sd",
            ">= 0",
        ),
        (
            "output_sd = 0.5",
            "output_sd = 0.5\noutput_ar = 1.0",
            Some(15),
            "noise.output_ar",
            "in (-1, 1)",
        ),
        (
            "output_sd = 0.5",
            "output_ar = 0.5",
            Some(14),
            "noise.output_ar",
            "add output_sd",
        ),
        (
            "[[parameter]]",
            "[[parameter]]\nname = \"b\"\n[[parameter]]",
            Some(5),
            "parameter",
            "1 parameter(s) (theta)",
        ),
    ];
    for (from, to, line, key, text) in cases {
        assert!(GOOD.contains(from), "{from}");
        let bad = GOOD.replacen(from, to, 1);
        let e = ModelFile::parse(&bad, "m.toml").map(|_| ()).unwrap_err();
        let message = e.to_string();
        match e {
            twostage::sources::Error::ModelFile {
                file,
                line: l,
                key: k,
                message: m,
            } => {
                assert_eq!(file, "m.toml");
                assert_eq!((l, k.as_str()), (*line, *key), "{from} -> {to}: {message}");
                assert!(m.contains(text), "{from} -> {to}: {message}");
            }
            other => panic!("{from} -> {to}: {other}"),
        }
    }
}

#[test]
fn presets_and_inputs_are_checked_too() {
    let with = |extra: &str| format!("{GOOD}{extra}");
    let cases: &[(&str, &str, &str)] = &[
        (
            "[[preset]]\nname = \"p\"\ncompress = \"arx:5\"\nfit = \"mlp:4\"\n",
            "preset.compress",
            "2 whole number(s)",
        ),
        (
            "[[preset]]\nname = \"p\"\ncompress = \"arx:2,2\"\nfit = \"net:4\"\n",
            "preset.fit",
            "use linear",
        ),
        (
            "[[preset]]\nname = \"p\"\ncompress = \"arx:2,2\"\nfit = \"mlp:4\"\nsims = 1\n",
            "preset.sims",
            "at least 2",
        ),
        ("[input]\nsignal = \"white\"\n", "input.sd", "needs sd"),
        (
            "[input]\nsignal = \"white\"\nsd = 1.0\namplitude = 2.0\n",
            "input.amplitude",
            "takes sd only",
        ),
        (
            "[input]\nsignal = \"square\"\n",
            "input.signal",
            "unknown signal 'square'",
        ),
        (
            "[input]\nsignal = \"white\"\nsd = -1.0\n",
            "input",
            "finite and > 0",
        ),
    ];
    for (extra, key, text) in cases {
        let e = ModelFile::parse(&with(extra), "m.toml")
            .map(|_| ())
            .unwrap_err();
        let line = common::named_line(&e, key, text);
        assert!(line.is_some_and(|l| l >= 15), "{e}");
    }
    let two = with(
        "[[preset]]\nname = \"p\"\ncompress = \"arx:2,2\"\nfit = \"linear\"\n[[preset]]\nname = \"p\"\ncompress = \"arx:3,3\"\nfit = \"linear\"\n",
    );
    assert!(
        ModelFile::parse(&two, "m.toml")
            .unwrap_err()
            .to_string()
            .contains("used twice")
    );
}

/// `[input] signal = "fixed", file = "record.csv"` hands a built-in model
/// the measured input, read from the file's column named as the input
/// (beside the model file), in every experiment; `--check` can then tell a
/// record on another input. A missing column is named with the file.
#[test]
fn a_measured_input_from_a_file_drives_a_built_in_model() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("measured-input");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let u: Vec<f64> = (0..50)
        .map(|k| ((k * 7) % 11) as f64 / 10.0 - 0.5)
        .collect();
    let mut csv = String::from("time,u,y\n");
    for (k, v) in u.iter().enumerate() {
        csv.push_str(&format!("{k},{v:?},0\n"));
    }
    std::fs::write(dir.join("record.csv"), csv).unwrap();
    let text = "[model]\nname = \"short\"\n[source]\nbuiltin = \"benchmark\"\n\
                [input]\nsignal = \"fixed\"\nfile = \"record.csv\"\n[signals]\nsamples = 50\n";
    std::fs::write(dir.join("short.toml"), text).unwrap();
    let file = ModelFile::load(dir.join("short.toml")).unwrap();
    let sim = file.simulator().unwrap();
    let mut record = sim.spec().new_record();
    sim.simulate(&[0.3], &mut experiment_rng(1, 4), &mut record)
        .unwrap();
    assert_eq!(record.input(0), u.as_slice());
    assert_eq!(sim.shared_input().unwrap().input(0), u.as_slice());
    // The same system on the same input, by the built-in model given it.
    let builtin = Benchmark::builder().n_samples(50).build().unwrap();
    let mut expected = builtin.spec().new_record();
    let quiet = twostage::models::Conditions {
        noiseless: true,
        input: Some(&record),
    };
    builtin
        .simulate_under(&[0.3], &mut experiment_rng(1, 4), quiet, &mut expected)
        .unwrap();
    let mut got = sim.spec().new_record();
    sim.simulate_under(
        &[0.3],
        &mut experiment_rng(1, 4),
        twostage::models::Conditions {
            noiseless: true,
            input: None,
        },
        &mut got,
    )
    .unwrap();
    assert_eq!(got.output(0), expected.output(0));
    // A file without the input's column.
    std::fs::write(dir.join("record.csv"), "time,v\n0,1\n").unwrap();
    let e = ModelFile::load(dir.join("short.toml"))
        .unwrap()
        .simulator()
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no column `u`") && e.contains("input.file"),
        "{e}"
    );
}

/// A fixed input can be a window of a larger file: a named column, a row
/// range; a window outside the file, or a column that is not there, is
/// named with the key, the file and the valid range.
#[test]
fn a_measured_input_is_a_window_of_a_larger_file() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("input-window");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let long: Vec<f64> = (0..200).map(|k| (k as f64 * 0.37).sin()).collect();
    let mut csv = String::from("t,voltage,position\n");
    for (k, v) in long.iter().enumerate() {
        csv.push_str(&format!("{k},{v:?},0\n"));
    }
    std::fs::write(dir.join("long.csv"), csv).unwrap();
    let model = |window: &str| {
        let text = format!(
            "[model]\nname = \"short\"\n[source]\nbuiltin = \"benchmark\"\n[input]\n\
             signal = \"fixed\"\nfile = \"long.csv\"\n{window}\n[signals]\nsamples = 50\n"
        );
        std::fs::write(dir.join("short.toml"), text).unwrap();
        ModelFile::load(dir.join("short.toml")).and_then(|f| f.simulator())
    };
    let sim = model("columns = [\"voltage\"]\nrows = [101, 150]").unwrap();
    assert_eq!(sim.shared_input().unwrap().input(0), &long[100..150]);
    let mut record = sim.spec().new_record();
    sim.simulate(&[0.3], &mut experiment_rng(1, 0), &mut record)
        .unwrap();
    assert_eq!(record.input(0), &long[100..150]);
    for (window, key, says) in [
        (
            "columns = [\"voltage\"]\nrows = [180, 229]",
            "input.rows",
            "data rows are 1 to 200",
        ),
        (
            "columns = [\"current\"]\nrows = [1, 50]",
            "input.file",
            "no column `current`",
        ),
        (
            "columns = [\"voltage\"]\nrows = [0, 49]",
            "input.rows",
            "counted from 1",
        ),
        ("rows = [1, 50]", "input.file", "no column `u`"),
    ] {
        let e = model(window).err().unwrap().to_string();
        assert!(
            e.contains(key) && e.contains(says) && e.contains("short.toml"),
            "{window}: {e}"
        );
    }
    // A window without a file has nothing to choose from.
    std::fs::write(
        dir.join("short.toml"),
        "[model]\nname = \"short\"\n[source]\nbuiltin = \"benchmark\"\n[input]\n\
         signal = \"white\"\nrows = [1, 50]\n[signals]\nsamples = 50\n",
    )
    .unwrap();
    let e = ModelFile::load(dir.join("short.toml"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("input.rows") && e.contains("give file"), "{e}");
}

/// `output_residual` shapes the file's output noise like a measured
/// residual: the noise the model adds has the residual's variance and
/// autocorrelations; mistakes name the key and the file.
#[test]
fn the_output_noise_can_take_a_measured_residuals_spectrum() {
    use twostage::models::ArNoise;
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("residual-noise");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A residual with two lags of memory: e_k = 1.2 e_(k-1) - 0.5 e_(k-2) + z_k.
    let mut residual = vec![0.0; 4000];
    let (mut rng, mut e1, mut e2) = (experiment_rng(9, 0), 0.0, 0.0);
    for v in residual.iter_mut() {
        let z: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
        let e = 1.2 * e1 - 0.5 * e2 + 0.1 * z;
        (e2, e1) = (e1, e);
        *v = e;
    }
    let mut csv = String::from("t,position\n");
    for (k, v) in residual.iter().enumerate() {
        csv.push_str(&format!("{k},{v:?}\n"));
    }
    std::fs::write(dir.join("residual.csv"), csv).unwrap();
    let text = |noise: &str| GOOD.replace("output_sd = 0.5", noise);
    std::fs::write(
        dir.join("shaped.toml"),
        text("output_residual = \"residual.csv\""),
    )
    .unwrap();
    let file = ModelFile::load(dir.join("shaped.toml")).unwrap();
    let added = added_noise(&file, 100, 2);
    // The same autocorrelations as the residual's, to sampling error.
    let correlations = |x: &[f64]| -> [f64; 3] {
        let c0: f64 = x.iter().map(|v| v * v).sum();
        let lag = |l: usize| x[l..].iter().zip(x).map(|(a, b)| a * b).sum::<f64>() / c0;
        [c0 / x.len() as f64, lag(1), lag(2)]
    };
    let (want, got) = (correlations(&residual), correlations(&added));
    assert!(
        (got[0] / want[0] - 1.0).abs() < 0.15,
        "variance {got:?} against {want:?}"
    );
    assert!(
        (got[1] - want[1]).abs() < 0.03 && (got[2] - want[2]).abs() < 0.05,
        "{got:?} {want:?}"
    );
    assert!(ArNoise::fit(&residual, 20, 0).order() >= 2);
    // Mistakes: together with output_sd; a column that is not there; too
    // short a residual.
    std::fs::write(
        dir.join("both.toml"),
        text("output_sd = 0.5\noutput_residual = \"residual.csv\""),
    )
    .unwrap();
    let e = ModelFile::load(dir.join("both.toml"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("noise.output_residual") && e.contains("leave out output_sd"),
        "{e}"
    );
    std::fs::write(dir.join("short.csv"), "position\n0.1\n0.2\n").unwrap();
    std::fs::write(dir.join("other.csv"), "velocity\n0.1\n").unwrap();
    for (csv, says) in [
        ("short.csv", "at least 50"),
        ("other.csv", "no column `position`"),
    ] {
        std::fs::write(
            dir.join("bad.toml"),
            text(&format!("output_residual = \"{csv}\"")),
        )
        .unwrap();
        let e = ModelFile::load(dir.join("bad.toml"))
            .and_then(|f| f.simulator())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("noise.output_residual") && e.contains(says) && e.contains("bad.toml"),
            "{e}"
        );
    }
}

/// Every model file the documentation shows loads: its keys, priors,
/// input design and equations are read as a user would read them (the
/// command sources are not started).
#[test]
fn every_example_model_file_loads() {
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/examples");
    let mut loaded = Vec::new();
    for folder in std::fs::read_dir(&examples).unwrap() {
        let folder = folder.unwrap().path();
        if !folder.is_dir() {
            continue;
        }
        for file in std::fs::read_dir(&folder).unwrap() {
            let file = file.unwrap().path();
            if file.extension().is_some_and(|e| e == "toml") {
                ModelFile::load(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
                loaded.push(file);
            }
        }
    }
    assert!(
        loaded
            .iter()
            .any(|f| f.ends_with("tanks/tanks7_equations.toml")),
        "{loaded:?}"
    );
}
