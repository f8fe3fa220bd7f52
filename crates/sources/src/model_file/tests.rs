use super::*;

#[test]
fn the_template_is_a_valid_model_file() {
    let file = ModelFile::parse(TEMPLATE, "template.toml").unwrap();
    // It simulates a record of its own shape, and names a preset.
    let simulator = file.simulator().unwrap();
    let mut record = simulator.spec().new_record();
    simulator
        .simulate(
            &[0.2],
            &mut twostage_models::experiment_rng(1, 0),
            &mut record,
        )
        .unwrap();
    assert_eq!((record.n_samples(), record.n_inputs()), (500, 1));
    assert!(record.output(0).iter().all(|y| y.is_finite()));
    assert_eq!(file.preset_names().collect::<Vec<_>>(), ["default"]);
}

/// The template's commented `[equations]` example, uncommented into a
/// file of its names, loads and simulates: the reference a user
/// copies from works.
#[test]
fn the_templates_equations_example_runs() {
    let block: Vec<&str> = TEMPLATE
        .lines()
        .skip_while(|l| !l.starts_with("#   [equations]"))
        .take_while(|l| l.starts_with("#   "))
        .map(|l| &l[4..])
        .collect();
    assert!(block.len() > 5, "the template has no [equations] example");
    let text = format!(
        "[model]\nname = \"level\"\n[[parameter]]\nname = \"k\"\n\
         prior = {{ dist = \"uniform\", low = 0.5, high = 2.0 }}\n[[parameter]]\n\
         name = \"h0\"\nprior = {{ dist = \"uniform\", low = 1.0, high = 3.0 }}\n\
         [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 40\n\
         [input]\nsignal = \"white\"\nsd = 0.5\n{}\n",
        block.join("\n")
    );
    let file = ModelFile::parse(&text, "level.toml").unwrap();
    let simulator = file.simulator().unwrap();
    let mut record = simulator.spec().new_record();
    simulator
        .simulate(
            &[1.0, 2.0],
            &mut twostage_models::experiment_rng(1, 0),
            &mut record,
        )
        .unwrap();
    // The level starts at h0 (measured at the start of sample 0).
    assert!((record.output(0)[0] - 2.0).abs() < 1e-12);
    assert!(record.output(0).iter().all(|y| y.is_finite()));
}

/// A value of the wrong type is named by its key and table, not only
/// its line.
#[test]
fn a_value_of_the_wrong_type_is_named_by_its_key() {
    let text = "[model]\nname = \"gain\"\n[[parameter]]\nname = \"k\"\n\
                prior = { dist = \"uniform\", low = 0.5, high = 2.0 }\n\
                [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 200\n\
                [input]\nsignal = \"binary\"\namplitude = 1.0\nhold = [1, 2]\n";
    let e = ModelFile::parse(text, "gain.toml").unwrap_err().to_string();
    assert!(
        e.starts_with("gain.toml, line 13, key `input.hold`: "),
        "{e}"
    );
    let inline = text
        .replace("low = 0.5", "low = [0.5]")
        .replace("hold = [1, 2]", "hold = 2");
    let e = ModelFile::parse(&inline, "gain.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 5, key `parameter.prior.low`"), "{e}");
}

/// A design's offset may be drawn per experiment like its other
/// settings; a range the wrong way round, or of three values, is
/// refused by its key and line.
#[test]
fn an_offset_is_drawn_per_experiment_from_its_range() {
    let file = |offset: &str| {
        format!(
            "[model]\nname = \"gain\"\n[[parameter]]\nname = \"k\"\n\
             prior = {{ dist = \"uniform\", low = 0.5, high = 2.0 }}\n\
             [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 200\n\
             [input]\nsignal = \"multisine\"\nband = [0.0, 0.2]\nrms = 0.1\n\
             offset = {offset}\n\
             [source]\nbuiltin = \"benchmark\"\n"
        )
    };
    let means = |text: &str| -> Vec<f64> {
        let simulator = ModelFile::parse(text, "gain.toml")
            .unwrap()
            .simulator()
            .unwrap();
        (0..6)
            .map(|k| {
                let mut record = simulator.spec().new_record();
                simulator
                    .simulate(
                        &[1.0],
                        &mut twostage_models::experiment_rng(2, k),
                        &mut record,
                    )
                    .unwrap();
                record.input(0).iter().sum::<f64>() / 200.0
            })
            .collect()
    };
    let drawn = means(&file("[4.0, 6.0]"));
    assert!(drawn.iter().all(|m| (3.9..6.1).contains(m)), "{drawn:?}");
    let spread = drawn.iter().copied().fold(f64::NAN, f64::max)
        - drawn.iter().copied().fold(f64::NAN, f64::min);
    assert!(spread > 0.3, "one offset per experiment: {drawn:?}");
    // One value, as before: every experiment about it.
    let fixed = means(&file("5.0"));
    assert!(fixed.iter().all(|m| (m - 5.0).abs() < 0.05), "{fixed:?}");
    for (bad, said) in [
        ("[6.0, 4.0]", "first no larger"),
        ("[1.0, 2.0, 3.0]", "3 values"),
    ] {
        let e = ModelFile::parse(&file(bad), "gain.toml")
            .and_then(|f| f.simulator().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("offset") && e.contains(said), "{bad}: {e}");
    }
}

/// A measured input whose lines fall to 0.65 of their level at the top
/// of its band (as a driven oscillator's amplifier makes them), 2000
/// samples of lines on the grid of 1000, its second half the record to
/// look like.
fn falling_lines_csv(dir: &std::path::Path) {
    let mut text = String::from("t,v\n");
    for t in 0..2000 {
        let v: f64 = (1..=200)
            .filter(|k| k % 2 == 1)
            .map(|k| {
                let level = 1.0 - 0.35 * f64::from(k) / 200.0;
                let phase = f64::from(k * k % 17);
                level * (std::f64::consts::TAU * f64::from(k * t) / 1000.0 + phase).cos()
            })
            .sum();
        text.push_str(&format!("{t},{v}\n"));
    }
    std::fs::write(dir.join("measured.csv"), text).unwrap();
}

/// `like` takes the lines' shape from a measured record beside the model
/// file, `spectrum` from a table; what no record could use is refused by
/// its key.
#[test]
fn a_design_s_lines_take_the_shape_of_a_measured_record() {
    let dir = std::env::temp_dir().join(format!("twostage-like-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    falling_lines_csv(&dir);
    let file = |shape: &str, kind: &str| {
        format!(
            "[model]\nname = \"gain\"\n[[parameter]]\nname = \"k\"\n\
             prior = {{ dist = \"uniform\", low = 0.5, high = 2.0 }}\n\
             [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 1000\n\
             [input]\nsignal = \"{kind}\"\nband = [0.0, 0.2]\nrms = 0.1\n{shape}\n\
             [source]\nbuiltin = \"benchmark\"\n"
        )
    };
    let load = |text: &str| {
        let path = dir.join("model.toml");
        std::fs::write(&path, text).unwrap();
        ModelFile::load(&path)
    };
    // The top of the band against its foot, in power over 0.17 to 0.2 and
    // 0.01 to 0.04 cycles per sample of records' shapes.
    let fall = |shapes: &[twostage_models::Spectrum]| {
        let (mut top, mut foot) = (0.0, 0.0);
        for [f, level] in shapes.iter().flat_map(|s| s.points()) {
            if (0.17..0.2).contains(f) {
                top += level * level;
            } else if (0.01..0.04).contains(f) {
                foot += level * level;
            }
        }
        (top / foot).sqrt()
    };
    // Five experiments' records.
    let records_fall = |text: &str| {
        let simulator = load(text).unwrap().simulator().unwrap();
        let shapes: Vec<twostage_models::Spectrum> = (0..5)
            .map(|experiment| {
                let mut record = simulator.spec().new_record();
                simulator
                    .simulate(
                        &[1.0],
                        &mut twostage_models::experiment_rng(4, experiment),
                        &mut record,
                    )
                    .unwrap();
                twostage_models::Spectrum::like(record.input(0)).unwrap()
            })
            .collect();
        fall(&shapes)
    };
    let like = "like = { file = \"measured.csv\", column = \"v\", rows = [1001, 2000] }";
    let measured = crate::csv_rows::read_columns(&dir.join("measured.csv"), &["v".into()]).unwrap();
    let expected = fall(&[twostage_models::Spectrum::like(&measured[0][1000..]).unwrap()]);
    assert!((expected - 0.68).abs() < 0.01, "{expected}");
    for kind in ["multisine", "gaussian"] {
        let got = records_fall(&file(like, kind));
        // The noise's lines are drawn: five experiments' bands of 30
        // lines, two Gaussian coordinates each, hold the ratio to some 5%.
        let tolerance = if kind == "multisine" { 0.02 } else { 0.12 };
        assert!(
            (got - expected).abs() < tolerance,
            "{kind}: {got} vs {expected}"
        );
    }
    let flat = records_fall(&file("", "multisine"));
    assert!((flat - 1.0).abs() < 0.02, "{flat}");
    let table = "spectrum = [[0.0, 1.0], [0.2, 0.65]]";
    let got = records_fall(&file(table, "multisine"));
    assert!((got - expected).abs() < 0.02, "{got} vs {expected}");
    for (shape, kind, key, said) in [
        (
            "like = { file = \"measured.csv\", column = \"w\" }",
            "multisine",
            "input.like.column",
            "no column `w` (the header has t, v)",
        ),
        (
            "like = { file = \"measured.csv\", column = \"v\", rows = [1, 2001] }",
            "multisine",
            "input.like.rows",
            "last <= 2000",
        ),
        (
            "like = { file = \"absent.csv\", column = \"v\" }",
            "multisine",
            "input.like.file",
            "absent.csv",
        ),
        (
            "like = { file = \".\", column = \"v\" }",
            "multisine",
            "input.like.file",
            "not a file",
        ),
        (
            "spectrum = [[0.0, 1.0], [0.7, 0.5]]",
            "multisine",
            "input",
            "above the Nyquist frequency 0.5 Hz",
        ),
        (
            "spectrum = [[0.2, 1.0], [0.1, 0.5]]",
            "multisine",
            "input.spectrum",
            "rising frequency",
        ),
        (
            &format!("{table}\n{like}"),
            "multisine",
            "input.like",
            "not both",
        ),
        (
            &format!("{table}\norder = 4"),
            "gaussian",
            "input.order",
            "give spectrum or like, or order",
        ),
    ] {
        let e = load(&file(shape, kind))
            .and_then(|f| f.simulator().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("key `{key}`")) && e.contains(said),
            "{shape}: {e}"
        );
    }
    let binary = "[model]\nname = \"gain\"\n[[parameter]]\nname = \"k\"\n\
                  prior = { dist = \"uniform\", low = 0.5, high = 2.0 }\n\
                  [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 100\n\
                  [input]\nsignal = \"binary\"\namplitude = 1.0\nhold = 2\n\
                  spectrum = [[0.0, 1.0]]\n[source]\nbuiltin = \"benchmark\"\n";
    let e = ModelFile::parse(binary, "b.toml").unwrap_err().to_string();
    assert!(
        e.contains("key `input.spectrum`") && e.contains("takes amplitude"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A band's bottom is drawn per experiment like its top: a range is read,
/// and one a noise's records cannot resolve is refused by its key.
#[test]
fn a_band_s_bottom_may_be_a_range() {
    let file = |kind: &str, band: &str| {
        format!(
            "[model]\nname = \"gain\"\n[[parameter]]\nname = \"k\"\n\
             prior = {{ dist = \"uniform\", low = 0.5, high = 2.0 }}\n\
             [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 400\n\
             [input]\nsignal = \"{kind}\"\nband = {band}\nrms = 0.1\n\
             [source]\nbuiltin = \"benchmark\"\n"
        )
    };
    let simulator = ModelFile::parse(&file("multisine", "[[0.02, 0.05], 0.2]"), "gain.toml")
        .unwrap()
        .simulator()
        .unwrap();
    let mut record = simulator.spec().new_record();
    simulator
        .simulate(
            &[1.0],
            &mut twostage_models::experiment_rng(2, 0),
            &mut record,
        )
        .unwrap();
    assert!(record.input(0).iter().all(|u| u.is_finite()));
    for (kind, band, said) in [
        ("gaussian", "[[0.0, 0.05], 0.2]", "noise band bottom"),
        ("multisine", "[[0.02, 0.3], 0.2]", "below the band's top"),
        ("multisine", "[[0.05, 0.02], 0.2]", "first no larger"),
    ] {
        let e = ModelFile::parse(&file(kind, band), "gain.toml")
            .and_then(|f| f.simulator().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("key `input") && e.contains(said), "{band}: {e}");
    }
}
