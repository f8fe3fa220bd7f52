//! Input designs in model files (issue 50): each experiment's input drawn
//! from its own stream, its settings drawn per experiment where a range
//! is given, and every impossible design named by line and key.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use twostage::ModelFile;
use twostage::models::{Simulator, experiment_rng};

/// Two tanks as equations, driven by `input` (an `[input]` table's body).
fn tanks(input: &str) -> String {
    format!(
        r#"[model]
name = "tanks"
[[parameter]]
name = "k"
prior = {{ dist = "uniform", low = 0.5, high = 1.5 }}
[signals]
inputs = ["pump"]
outputs = ["level"]
samples = 400
sample_time = 2.0
[input]
{input}
[equations]
substeps = 4
inputs = "hold"
states = [
  {{ name = "h1", initial = 2, derivative = "k * pump - sqrt(max(h1, 0))" }},
  {{ name = "h2", initial = 2, derivative = "sqrt(max(h1, 0)) - sqrt(max(h2, 0))" }},
]
outputs = {{ level = "h2" }}
"#
    )
}

/// The input of experiment `i` of seed 7 (at the prior's lower corner).
fn input_of(file: &ModelFile, i: u64) -> Vec<f64> {
    let sim = file.simulator().unwrap();
    let mut record = sim.spec().new_record();
    let theta = sim.spec().prior().lower().to_vec();
    sim.simulate(&theta, &mut experiment_rng(7, i), &mut record)
        .unwrap();
    record.input(0).to_vec()
}

#[test]
fn each_experiment_draws_its_own_multisine_in_the_family() {
    let file = ModelFile::parse(
        &tanks(
            "signal = \"multisine\"\nband = [0.0, [0.02, 0.1]]\ngrid = \"odd\"\n\
             rms = [0.3, 0.8]\noffset = 2.5",
        ),
        "tanks.toml",
    )
    .unwrap();
    let inputs: Vec<Vec<f64>> = (0..4).map(|i| input_of(&file, i)).collect();
    let mut levels = Vec::new();
    for u in &inputs {
        let n = u.len() as f64;
        let mean = u.iter().sum::<f64>() / n;
        let rms = (u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!((mean - 2.5).abs() < 1e-9, "{mean}");
        assert!((0.3..=0.8).contains(&rms), "{rms}");
        levels.push(rms);
    }
    // Each experiment its own input and its own level; the same stream,
    // the same bits.
    assert!(inputs.windows(2).all(|w| w[0] != w[1]));
    assert!(levels.windows(2).all(|w| (w[0] - w[1]).abs() > 1e-6));
    assert_eq!(inputs[2], input_of(&file, 2));
    let described = file.simulator().unwrap().spec().input_note().to_string();
    assert!(
        described.contains("random-phase multisine on the odd grid")
            && described.contains("0.02 to 0.1 Hz (drawn per experiment)"),
        "{described}"
    );
    // The other designs parse and draw too.
    for design in [
        "signal = \"binary\"\namplitude = 0.5\nhold = 5\noffset = 2",
        "signal = \"prbs\"\norder = 7\namplitude = [0.2, 0.6]\nhold = 3\noffset = 2",
        "signal = \"sweep\"\nband = [0.001, 0.1]\namplitude = 0.5\noffset = 2",
        "signal = \"gaussian\"\nband = [0.005, [0.05, 0.1]]\norder = 3\nrms = [0.1, 0.3]\noffset = 2",
        "signal = \"steps\"\nlevels = [1.0, 3.5]\nhold_seconds = [20, 60]",
        "signal = \"bursts\"\ncount = [1, 3]\nseconds = [40, 200]\ncycles = [0.5, 2.5]\n\
         amplitude = [0.2, 0.5]\ntaper = \"mixed\"\noffset = 2",
        "signal = \"bursts\"\ncount = [1, 2]\nseconds = [40, 200]\ncycles = [0.5, 2.5]\n\
         amplitude = [0.2, 0.5]\ndwell = [0, 30]\noffset = 2",
        "signal = \"sum\"\nparts = [\n  { signal = \"steps\", levels = [1.5, 3], hold_seconds = [40, 80] },\n  \
         { signal = \"multisine\", band = [0.0, 0.05], rms = 0.2 },\n]",
    ] {
        let file = ModelFile::parse(&tanks(design), "tanks.toml").unwrap();
        let (a, b) = (input_of(&file, 0), input_of(&file, 1));
        assert!(a.iter().all(|v| v.is_finite() && *v > 0.9), "{design}");
        if !design.contains("sweep") {
            assert_ne!(a, b, "{design}");
        }
    }
}

#[test]
fn a_sample_time_whose_record_ends_past_the_largest_time_is_refused_by_its_key() {
    let text = tanks("signal = \"chicane\"\namplitude = 0.2")
        .replace("sample_time = 2.0", "sample_time = 0.1e308");
    let message = ModelFile::parse(&text, "far.toml").unwrap_err().to_string();
    for part in [
        "far.toml",
        "line 10",
        "signals.sample_time",
        "400 samples 1e307 apart",
        "give at most 4.49",
    ] {
        assert!(message.contains(part), "{part} not in: {message}");
    }
    // Just inside, the file reads, and a step of 8e305 makes the
    // record fail with the state named, not the process.
    let text = tanks("signal = \"chicane\"\namplitude = 0.2")
        .replace("sample_time = 2.0", "sample_time = 4e305");
    let sim = ModelFile::parse(&text, "far.toml")
        .unwrap()
        .simulator()
        .unwrap();
    let mut record = sim.spec().new_record();
    let theta = sim.spec().prior().lower().to_vec();
    let failed = sim
        .simulate(&theta, &mut experiment_rng(7, 0), &mut record)
        .unwrap_err();
    assert!(failed.to_string().contains("h2"), "{failed}");
}

#[test]
fn substeps_beyond_the_limit_are_refused_by_their_key() {
    let text = tanks("signal = \"chicane\"\namplitude = 0.2")
        .replace("substeps = 4", "substeps = 1000000000000");
    let message = ModelFile::parse(&text, "steps.toml")
        .unwrap_err()
        .to_string();
    for part in [
        "steps.toml",
        "line 15",
        "equations.substeps",
        "from 1 to 100000, not 1000000000000",
    ] {
        assert!(message.contains(part), "{part} not in: {message}");
    }
    let text =
        tanks("signal = \"chicane\"\namplitude = 0.2").replace("substeps = 4", "substeps = 100000");
    assert!(ModelFile::parse(&text, "steps.toml").is_ok());
}

#[test]
fn an_impossible_design_is_named_by_its_key() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "signal = \"multisine\"\nband = [0.0, 0.5]",
            "input",
            "above the Nyquist frequency 0.25 Hz",
        ),
        (
            "signal = \"multisine\"\nband = [0.0, 0.1]\nrms = [0.8, 0.3]",
            "input.rms",
            "the first no larger than the second",
        ),
        (
            "signal = \"multisine\"\nband = [0.0, 0.1]\nhold = 3",
            "input.hold",
            "takes band, grid, phases, rms, peak, offset, spectrum, like only",
        ),
        (
            "signal = \"multisine\"\nband = [0.0, 0.1]\nrms = 1\npeak = 2",
            "input.peak",
            "rms or peak, not both",
        ),
        (
            "signal = \"multisine\"\nband = [0.0, 0.1]\ngrid = \"even\"",
            "input.grid",
            "use \"full\" or \"odd\"",
        ),
        (
            "signal = \"gaussian\"\nband = [0.0, 0.3]\nrms = 1",
            "input",
            "above the Nyquist frequency 0.25 Hz",
        ),
        (
            // 400 samples every 2 s resolve 1/800 Hz: said when the file is
            // read, not by every experiment of a training run.
            "signal = \"gaussian\"\nband = [0.001, 0.1]\nrms = 1",
            "input",
            "below the record's resolution 1/(N T) = 0.00125 Hz",
        ),
        (
            "signal = \"gaussian\"\nband = [0.0, [0.0005, 0.1]]\nrms = 1",
            "input",
            "below the record's resolution",
        ),
        (
            "signal = \"gaussian\"\nband = [0.0, 0.1]\nrms = 1\norder = 12",
            "input",
            "1 to 10",
        ),
        (
            "signal = \"gaussian\"\nband = [0.0, 0.1]\namplitude = 1",
            "input.amplitude",
            "takes band, order, rms, offset, spectrum, like only",
        ),
        (
            "signal = \"prbs\"\namplitude = 1\nhold = 1",
            "input.order",
            "needs order",
        ),
        (
            "signal = \"prbs\"\norder = 40\namplitude = 1\nhold = 1",
            "input",
            "2 to 20",
        ),
        (
            "signal = \"binary\"\namplitude = 1\nhold = 0",
            "input",
            "at least 1 sample",
        ),
        (
            "signal = \"chicane\"\namplitude = [0.1, 0.2]",
            "input.amplitude",
            "one amplitude",
        ),
        (
            "signal = \"steps\"\nlevels = [1, 2]\nhold_seconds = [5, 1]",
            "input",
            "0 < shortest <= longest",
        ),
        (
            "signal = \"bursts\"\ncount = [0, 2]\nseconds = 50\ncycles = 1\namplitude = 1",
            "input",
            "1 <= low <= high",
        ),
        (
            "signal = \"bursts\"\ncount = [1.5, 2]\nseconds = 50\ncycles = 1\namplitude = 1",
            "input.count",
            "whole numbers",
        ),
        (
            "signal = \"bursts\"\nseconds = 50\ncycles = [0.6, 0.9]\namplitude = 1",
            "input",
            "no whole number of half cycles",
        ),
        (
            "signal = \"bursts\"\nseconds = 50\ncycles = 1\namplitude = 1\ntaper = \"cosine\"",
            "input.taper",
            "use \"hann\", \"none\" or \"mixed\"",
        ),
        (
            "signal = \"bursts\"\nseconds = 50\ncycles = 1\namplitude = 1\ndwell = [-1, 2]",
            "input",
            "a crest is held zero seconds or more",
        ),
        (
            "signal = \"bursts\"\nseconds = 50\ncycles = 1\namplitude = 1\ndwell = [2, 1]",
            "input.dwell",
            "the first no larger than the second",
        ),
        (
            "signal = \"bursts\"\nseconds = [4, 8]\ncycles = 2\namplitude = 1",
            "input",
            "above the Nyquist frequency 0.25 Hz",
        ),
        (
            "signal = \"bursts\"\nseconds = 50\namplitude = 1",
            "input.cycles",
            "needs seconds, cycles, amplitude",
        ),
        (
            "signal = \"sum\"\nparts = [{ signal = \"white\", sd = 1 }]",
            "input",
            "two or more",
        ),
        (
            "signal = \"sum\"\nparts = [{ signal = \"white\", sd = 1 }, { signal = \"sum\", \
             parts = [] }]",
            "input.parts",
            "a part of a sum is one design",
        ),
        (
            "signal = \"sum\"\nparts = [{ signal = \"white\", sd = 1 }, { signal = \"prbs\" }]",
            "input.order",
            "needs order",
        ),
        (
            "signal = \"mix\"\nparts = []",
            "input.parts",
            "needs one or more parts",
        ),
        (
            "signal = \"mix\"\nparts = [{ signal = \"white\", sd = 1 }, \
             { signal = \"white\", sd = 2 }]\nweights = [1]",
            "input.weights",
            "give one per part",
        ),
        (
            "signal = \"mix\"\nparts = [{ signal = \"white\", sd = 1 }, \
             { signal = \"white\", sd = 2 }]\nweights = [1, 0]",
            "input",
            "0 for part 2",
        ),
        (
            "signal = \"sequence\"\nparts = [{ signal = \"white\", sd = 1 }]",
            "input",
            "two or more",
        ),
        (
            "signal = \"ramps\"\nlevels = [-1, 1]\nhold_seconds = [0, 5]",
            "input",
            "ramps hold_seconds = 0: a level is held a positive time",
        ),
        (
            "signal = \"ramps\"\nlevels = [-1, 1]\nhold_seconds = [2, 5]\nramp_seconds = [-1, 2]",
            "input",
            "ramps ramp_seconds = -1",
        ),
        (
            "signal = \"ramps\"\nhold_seconds = [2, 5]",
            "input.levels",
            "needs levels, hold_seconds",
        ),
    ];
    for (design, key, text) in cases {
        let e = ModelFile::parse(&tanks(design), "tanks.toml")
            .map(|_| ())
            .unwrap_err();
        let line = common::named_line(&e, key, text);
        assert!(line.is_some(), "{design}: {e}");
    }
}

/// The family of docs/accuracy.md's measurement loads and draws as said.
#[test]
fn the_documented_family_loads_and_draws_its_own_inputs() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/tanks/tanks_multisine.toml");
    let file = ModelFile::load(&path).unwrap();
    let (a, b) = (input_of(&file, 0), input_of(&file, 1));
    assert_ne!(a, b);
    let mean = a.iter().sum::<f64>() / a.len() as f64;
    assert!((mean - 2.2).abs() < 1e-9, "{mean}");
    assert!(
        file.simulator()
            .unwrap()
            .spec()
            .input_note()
            .contains("odd grid")
    );
}

/// An estimator trained on a family judges each record's input against
/// it: the family's own records pass (all but a few in a thousand), and
/// an input of a level or a band the training never had is flagged, with
/// the number that lies outside; the file keeps the family and `describe`
/// names it.
#[test]
fn an_estimator_of_a_family_flags_an_input_outside_it() {
    let file = ModelFile::parse(
        &tanks(
            "signal = \"multisine\"\nband = [0.0, [0.02, 0.05]]\ngrid = \"odd\"\n\
             rms = [0.3, 0.6]\noffset = 2.5",
        ),
        "tanks.toml",
    )
    .unwrap();
    let sim = file.simulator().unwrap();
    let estimator = twostage::TwoStage::builder(sim.as_ref())
        .compressor(twostage::compress::Arx::new(2, 2).unwrap())
        .linear(1e-6)
        .unwrap()
        .simulations(200)
        .calibration(300)
        .validation(200)
        .seed(3)
        .train()
        .unwrap();
    let family = estimator
        .input_family()
        .expect("trained on simulations: a family");
    assert_eq!(family.records(), 500);
    let bytes = estimator.to_bytes().unwrap();
    assert_eq!(twostage::Estimator::from_bytes(&bytes).unwrap(), estimator);
    let described = family.describe(&["pump"]).join("\n");
    assert!(
        described.starts_with("pump: mean 2.5") && described.contains("RMS 0.3"),
        "{described}"
    );

    // The family's own fresh records: at most a few flagged.
    let theta = [1.0];
    let flagged = (0..1000)
        .filter(|&i| {
            let mut record = sim.spec().new_record();
            sim.simulate(&theta, &mut experiment_rng(77, i), &mut record)
                .unwrap();
            !estimator
                .assess(&record)
                .unwrap()
                .input_deviations
                .is_empty()
        })
        .count();
    assert!(flagged <= 5, "{flagged} of 1000 family records flagged");

    // Another level, another band: each flagged by what lies outside.
    let outside = |design: &str| {
        let other = ModelFile::parse(&tanks(design), "other.toml").unwrap();
        let sim = other.simulator().unwrap();
        let mut record = sim.spec().new_record();
        sim.simulate(&theta, &mut experiment_rng(78, 0), &mut record)
            .unwrap();
        let assessment = estimator.assess(&record).unwrap();
        assert!(assessment.out_of_distribution(), "{design}");
        assessment
            .input_deviations
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
    };
    let loud = outside(
        "signal = \"multisine\"\nband = [0.0, 0.03]\ngrid = \"odd\"\nrms = 1.5\noffset = 2.5",
    );
    assert!(
        loud.iter()
            .any(|s| s.starts_with("input pump: RMS 1.5") && s.contains("above")),
        "{loud:?}"
    );
    let fast = outside(
        "signal = \"multisine\"\nband = [0.1, 0.2]\ngrid = \"odd\"\nrms = 0.45\noffset = 2.5",
    );
    assert!(
        fast.iter()
            .any(|s| s.contains("mean frequency") && s.contains("above")),
        "{fast:?}"
    );
    assert!(!fast.iter().any(|s| s.contains("RMS")), "{fast:?}");
}

/// The car's family of manoeuvres (docs/examples/car/car_manoeuvres.toml)
/// draws records that rest and steer, and holds the paper's chicane as
/// one of its kind: the chicane's input summary lies inside the range of
/// the family's records, though no record is the chicane.
#[test]
fn the_car_family_of_manoeuvres_holds_the_chicane_among_its_kind() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/car/car_manoeuvres.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let sim = ModelFile::parse(&text, &path.display().to_string())
        .unwrap()
        .simulator()
        .unwrap();
    let spec = sim.spec();
    let described = spec.input_note().to_string();
    assert!(
        described.contains("random bursts, 1 to 2 per record")
            && described.contains("0.5 to 2.5 cycles")
            && described.contains("over 2 to 8 s"),
        "{described}"
    );
    let mut family = twostage::models::InputFamily::new(1, spec.sample_time());
    let theta = spec.prior().lower().to_vec();
    let mut resting = 0;
    for i in 0..500 {
        let mut record = spec.new_record();
        sim.simulate(&theta, &mut experiment_rng(7, i), &mut record)
            .unwrap();
        let u = record.input(0);
        assert!(u.iter().all(|v| v.abs() <= 0.5), "{i}: two bursts at most");
        resting += usize::from(u.iter().filter(|v| **v == 0.0).count() >= 50);
        family.include(&record);
    }
    // At least a second of rest in most records.
    assert!(resting >= 400, "{resting} of 500 records rest a second");
    let car = twostage::models::PacejkaCar::new();
    let mut chicane = car.spec().new_record();
    car.simulate(&[-35.0, -1.1], &mut experiment_rng(7, 0), &mut chicane)
        .unwrap();
    let outside = family.deviations(&chicane, &["delta"]);
    assert!(outside.is_empty(), "{outside:?}");
}

/// The car's family of ordinary driving (docs/examples/car/car_driving.toml)
/// draws one kind of driving per experiment by weight: records steered
/// by noise throughout (the random steering and the held corner with
/// corrections, 3 of 10 weights) and records that start from rest
/// (bursts, ramps and their sequence, 7 of 10), each in about its share.
#[test]
fn the_car_family_of_ordinary_driving_draws_each_kind_by_its_weight() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/car/car_driving.toml");
    let file = ModelFile::load(&path).unwrap();
    let sim = file.simulator().unwrap();
    let described = sim.spec().input_note().to_string();
    assert!(
        described.contains("one per experiment: 0.300 of them random bursts")
            && described.contains("0.100 of them the sum")
            && described.contains("0.200 of them in turn"),
        "{described}"
    );
    let (mut noisy, mut resting) = (0, 0);
    let records = 600;
    for i in 0..records {
        let u = input_of(&file, i);
        let steered_throughout =
            u.iter().all(|v| *v != 0.0) && u.windows(2).all(|w| w[0].to_bits() != w[1].to_bits());
        noisy += usize::from(steered_throughout);
        resting += usize::from(u[0] == 0.0);
        if i < 3 {
            assert_eq!(u, input_of(&file, i), "the same stream, the same bits");
        }
    }
    assert_eq!(noisy + resting, records as usize, "{noisy} + {resting}");
    // A binomial share 0.3 of 600: sd 0.019.
    let share = noisy as f64 / records as f64;
    assert!((0.23..=0.37).contains(&share), "{share} steered throughout");
}

/// The car's family of sine bursts between rests (docs/examples/car):
/// its estimator keeps a density of the held-out records' input shapes.
/// Its own fresh records pass but about one in a hundred; a step steer
/// and a slalom, whose level, size and mean frequency lie inside the
/// family's ranges, are flagged by their shape alone; the file keeps the
/// shapes, and a file of format 5 (the same bytes without them) still
/// reads, without them.
#[test]
fn a_steer_of_another_shape_than_the_familys_is_flagged() {
    use twostage::models::{BuiltinModel, BuiltinOverrides, InputSignal};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../docs/examples/car/car_manoeuvres.toml");
    let file = ModelFile::load(&path).unwrap();
    let sim = file.simulator().unwrap();
    let estimator = twostage::TwoStage::builder(sim.as_ref())
        .compressor(twostage::compress::Arx::new(2, 2).unwrap())
        .linear(1e-6)
        .unwrap()
        .simulations(200)
        .calibration(1500)
        .validation(700)
        .seed(5)
        .train()
        .unwrap();
    let shapes = estimator
        .input_shapes()
        .expect("inputs that differ: shapes");
    assert_eq!(shapes.len(), twostage::models::SHAPE_SAMPLE / 2);
    let bytes = estimator.to_bytes().unwrap();
    assert_eq!(twostage::Estimator::from_bytes(&bytes).unwrap(), estimator);

    let theta = [-35.0, -1.1];
    let assess = |record: &twostage::models::IoData| estimator.assess(record).unwrap();
    let flagged = (0..400)
        .filter(|&i| {
            let mut record = sim.spec().new_record();
            sim.simulate(&theta, &mut experiment_rng(91, i), &mut record)
                .unwrap();
            assess(&record).input_shape_outside()
        })
        .count();
    assert!(flagged <= 12, "{flagged} of 400 family records flagged");

    let driven = |steering: Vec<f64>| {
        let overrides = BuiltinOverrides {
            input: Some(InputSignal::fixed(steering).unwrap()),
            ..BuiltinOverrides::default()
        };
        let car = BuiltinModel::Pacejka.build_with(&overrides).unwrap();
        let mut record = car.spec().new_record();
        car.simulate(&theta, &mut experiment_rng(92, 0), &mut record)
            .unwrap();
        assess(&record)
    };
    let at = |k: usize| k as f64 * 0.02;
    let step = driven(
        (0..500)
            .map(|k| 0.1 * ((at(k) - 1.0) / 0.15).clamp(0.0, 1.0))
            .collect(),
    );
    let slalom = driven(
        (0..500)
            .map(|k| {
                let t = at(k) - 1.0;
                if (0.0..8.0).contains(&t) {
                    0.1 * (std::f64::consts::TAU * 0.5 * t).sin()
                } else {
                    0.0
                }
            })
            .collect(),
    );
    for (name, a) in [("step", &step), ("slalom", &slalom)] {
        assert!(
            a.input_deviations.is_empty(),
            "{name}: {:?}",
            a.input_deviations
        );
        assert!(
            a.input_shape_outside() && a.out_of_distribution(),
            "{name}: {:?} beyond {:?}",
            a.input_shape_distance,
            a.input_shape_threshold
        );
    }

    // Format 5: the header's version 5, the payload without the shapes
    // (postcard writes `None` as one zero byte, `Some` as a one first).
    let mut without = estimator.clone().with_input_family(None);
    without = without.with_input_family(estimator.input_family().cloned());
    assert!(without.input_shapes().is_none());
    let mut old = without.to_bytes().unwrap();
    assert_eq!(old.pop(), Some(0));
    old[8..12].copy_from_slice(&5u32.to_le_bytes());
    let length = (old.len() - 24) as u64;
    old[12..20].copy_from_slice(&length.to_le_bytes());
    let crc = crc32(&old[24..]);
    old[20..24].copy_from_slice(&crc.to_le_bytes());
    let read = twostage::Estimator::from_bytes(&old).unwrap();
    assert!(read.input_shapes().is_none());
    assert_eq!(read.input_family(), estimator.input_family());
}

/// CRC-32 (IEEE 802.3), bit by bit: the estimator file's checksum.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}
