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
