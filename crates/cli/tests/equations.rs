//! Models written as equations in their model file: the
//! examples' equations give their Python simulators' noise-free records,
//! they train through every door, and their mistakes are named at load.

// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{path, python, scratch, text, twostage};

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/examples")
}

/// `simulate --theta` without noise: the outputs, column by column.
fn noise_free(model: &Path, theta: &str) -> Vec<Vec<f64>> {
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(model),
        "--theta",
        theta,
        "--noiseless",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let mut lines = stdout.lines();
    let width = lines.next().unwrap().split(',').count();
    let mut columns = vec![Vec::new(); width];
    for line in lines {
        for (j, cell) in line.split(',').enumerate() {
            columns[j].push(cell.parse::<f64>().unwrap());
        }
    }
    columns
}

/// `file`'s text with its Python command run by the test's Python, in `dir`.
fn with_python(dir: &Path, folder: &str, file: &str, program: &str) -> PathBuf {
    let text = std::fs::read_to_string(examples().join(folder).join(file)).unwrap();
    let command = format!(
        "[{:?}, {:?}]",
        python(),
        examples().join(folder).join(program).to_str().unwrap()
    );
    let text = text.replace(&format!(r#"["python3", "{program}"]"#), &command);
    assert!(
        text.contains(&command),
        "{file} names its command otherwise"
    );
    let out = dir.join(file);
    std::fs::write(&out, text).unwrap();
    out
}

fn assert_close(a: &[Vec<f64>], b: &[Vec<f64>], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: columns");
    for (ca, cb) in a.iter().zip(b) {
        assert_eq!(ca.len(), cb.len(), "{what}: samples");
        for (k, (x, y)) in ca.iter().zip(cb).enumerate() {
            assert!(
                (x - y).abs() <= 1e-9 * (1.0 + y.abs()),
                "{what}, sample {k}: {x} against {y}"
            );
        }
    }
}

#[test]
fn the_examples_equations_give_their_simulators_noise_free_records() {
    let dir = scratch("equations-examples");
    // SIR: the same Euler steps as sir.py.
    let sir = with_python(&dir, "sir", "sir.toml", "sir.py");
    let sir_equations = examples().join("sir/sir_equations.toml");
    for theta in ["0.4,0.1", "0.25,0.2", "0.9,0.05"] {
        let by_python = noise_free(&sir, theta);
        assert_close(&noise_free(&sir_equations, theta), &by_python, "sir");
    }
    // Tanks: RK4 with the measured pump voltage held between samples.
    let made = Command::new(python())
        .arg(examples().join("tanks/make_data.py"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", text(&made.stderr));
    let tanks = with_python(&dir, "tanks", "tanks.toml", "tanks.py");
    let tanks_equations = dir.join("tanks_equations.toml");
    std::fs::copy(
        examples().join("tanks/tanks_equations.toml"),
        &tanks_equations,
    )
    .unwrap();
    for theta in ["1,1,1,5", "1.3,0.7,1.2,0.8", "0.8,1.4,0.6,9"] {
        let by_python = noise_free(&tanks, theta);
        assert_close(&noise_free(&tanks_equations, theta), &by_python, "tanks");
    }
    // Lotka-Volterra: lv.py's populations at the same rates.
    let lv_equations = examples().join("lotka-volterra/lv_equations.toml");
    for theta in ["0.8,0.05,0.05,0.8", "1.1,0.04,0.06,0.6"] {
        let script = format!(
            "import sys; sys.path.insert(0, {:?}); import lv, numpy as np\n\
             p = lv.populations(np.array([[{theta}]]))[0]\n\
             print('\\n'.join('%r,%r' % (float(x), float(y)) for x, y in p))",
            examples().join("lotka-volterra").to_str().unwrap()
        );
        let out = Command::new(python())
            .arg("-c")
            .arg(&script)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", text(&out.stderr));
        let mut by_python = vec![Vec::new(), Vec::new()];
        for line in text(&out.stdout).lines() {
            for (j, cell) in line.split(',').enumerate() {
                by_python[j].push(cell.parse::<f64>().unwrap());
            }
        }
        assert_close(
            &noise_free(&lv_equations, theta),
            &by_python,
            "lotka-volterra",
        );
    }
}

#[test]
fn an_equations_model_trains_and_estimates_through_the_shell() {
    let dir = scratch("equations-train");
    let model = examples().join("sir/sir_equations.toml");
    let estimator = dir.join("sir.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--sims",
        "1500",
        "--validate",
        "300",
        "--calibrate",
        "300",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report = text(&out.stdout);
    // beta's prior sd is about 0.2 (log-normal, sigma 0.5 about 0.4):
    // the estimator learns it to a small share of that.
    let rmse: f64 = report
        .lines()
        .find(|l| l.trim_start().starts_with("beta") && l.contains("RMSE"))
        .and_then(|l| l.split("RMSE").nth(1))
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("{report}"))
        .parse()
        .unwrap();
    assert!(rmse < 0.05, "{report}");
    // Records of the model, estimated, checked against it and refined
    // through it where the check does not explain the two-stage estimate.
    let data = dir.join("data");
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&model),
        "--count",
        "5",
        "--seed",
        "9",
        "--out-dir",
        path(&data),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = twostage(&[
        "estimate",
        "--estimator",
        path(&estimator),
        "--model-file",
        path(&model),
        "--refine=auto",
        path(&data.join("data.csv")),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let header: Vec<&str> = stdout.lines().next().unwrap().split(',').collect();
    let explained = header.iter().position(|h| *h == "explained").unwrap();
    let rows: Vec<&str> = stdout.lines().skip(1).collect();
    assert_eq!(rows.len(), 5);
    assert!(
        rows.iter()
            .all(|r| r.split(',').nth(explained) == Some("true")),
        "{stdout}"
    );
}

/// A model file of the first-order lag with `equations` as its table.
fn lag_file(dir: &Path, equations: &str) -> PathBuf {
    let file = dir.join("lag.toml");
    std::fs::write(
        &file,
        format!(
            "[model]\nname = \"lag\"\n\n[[parameter]]\nname = \"tau\"\n\
             prior = {{ dist = \"uniform\", low = 0.5, high = 2.0 }}\n\n\
             [signals]\ninputs = [\"u\"]\noutputs = [\"y\"]\nsamples = 50\nsample_time = 0.1\n\n\
             [input]\nsignal = \"white\"\nsd = 1.0\n\n[equations]\n{equations}"
        ),
    )
    .unwrap();
    file
}

fn refusal(file: &Path) -> String {
    let out = twostage(&["simulate", "--model-file", path(file), "--theta", "1"]);
    assert!(!out.status.success());
    text(&out.stderr)
}

#[test]
fn mistakes_in_equations_are_named_with_file_line_and_position() {
    let dir = scratch("equations-mistakes");
    let states = "states = [{ name = \"x\", initial = 0, derivative = \"(u - x) / tau\" }]\n";
    // A syntax error: the file, the line of the equation, its position.
    let file = lag_file(&dir, &format!("{states}outputs = {{ y = \"x * (2 +\" }}\n"));
    let stderr = refusal(&file);
    assert!(
        stderr.contains("lag.toml") && stderr.contains("line 20"),
        "{stderr}"
    );
    assert!(
        stderr.contains("equations.y") && stderr.contains("cannot parse"),
        "{stderr}"
    );
    // An unknown name, with the known ones and where it is.
    let file = lag_file(&dir, &format!("{states}outputs = {{ y = \"x + k\" }}\n"));
    let stderr = refusal(&file);
    assert!(stderr.contains("at character 5"), "{stderr}");
    assert!(
        stderr.contains("unknown name `k`; known: t, tau, u, x, y"),
        "{stderr}"
    );
    // A cycle among the defined quantities.
    let file = lag_file(
        &dir,
        &format!("{states}define = {{ p = \"q\", q = \"p + x\" }}\noutputs = {{ y = \"p\" }}\n"),
    );
    assert!(refusal(&file).contains("in a cycle: p -> q -> p"));
    // A discrete model's state given a derivative.
    let file = lag_file(
        &dir,
        "time = \"discrete\"\nstates = [{ name = \"x\", initial = 0, derivative = \"x\" }]\n\
         outputs = { y = \"x\" }\n",
    );
    assert!(refusal(&file).contains("this model's states take `next`"));
    // Both a source and equations.
    let both = dir.join("both.toml");
    let text_of = std::fs::read_to_string(lag_file(
        &dir,
        &format!("{states}outputs = {{ y = \"x\" }}\n"),
    ))
    .unwrap();
    std::fs::write(
        &both,
        format!("{text_of}\n[source]\nbuiltin = \"benchmark\"\n"),
    )
    .unwrap();
    assert!(refusal(&both).contains("leave out [source]"));
    // And the same file without the mistake runs.
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(&lag_file(
            &dir,
            &format!("{states}outputs = {{ y = \"x\" }}\n"),
        )),
        "--theta",
        "1",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

/// Training arguments shared by the single-machine run and the merge.
fn small_design<'a>(model: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        "--model-file",
        model,
        "--compress",
        "raw",
        "--fit",
        "mlp:4",
        "--out",
        out,
        "--quiet",
    ]
}

#[test]
fn an_equations_model_goes_through_shards_and_the_automatic_design() {
    let dir = scratch("equations-doors");
    let model = examples().join("sir/sir_equations.toml");
    let sizes = [
        "--count",
        "300",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--seed",
        "3",
    ];
    // Shards merge to the file one machine writes: the equations draw
    // their noise from each experiment's own stream.
    let single = dir.join("single.tsest");
    let mut args = small_design(path(&model), path(&single));
    args.extend([
        "--sims",
        "300",
        "--validate",
        "100",
        "--calibrate",
        "100",
        "--seed",
        "3",
    ]);
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let shards = dir.join("shards");
    for shard in ["0/2", "1/2"] {
        let mut args = vec!["simulate", "--model-file", path(&model)];
        args.extend(sizes);
        args.extend(["--shard", shard, "--out", path(&shards)]);
        let out = twostage(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    let pattern = format!("{}/shard-*", shards.display());
    let merged = dir.join("merged.tsest");
    let mut args = small_design(path(&model), path(&merged));
    args.extend(["--chart", &pattern]);
    let out = twostage(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(),
        "the merged estimator file differs from the single-machine one"
    );
    // The automatic design searches an equations model as any other.
    let searched = dir.join("searched.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&model),
        "--auto",
        "--budget-seconds",
        "15",
        "--validate",
        "200",
        "--calibrate",
        "200",
        "--out",
        path(&searched),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report = text(&out.stdout);
    assert!(report.contains("automatic design on m = "), "{report}");
    assert!(searched.exists());
}

/// An estimator trained on the multisine family of the tanks: `inspect`
/// names the family, `estimate` finds the family's records inside it and
/// flags a record of a level the training never had, saying which number
/// of which input lies outside.
#[test]
fn estimate_judges_each_record_s_input_against_the_family() {
    let dir = scratch("equations-family");
    let family = examples().join("tanks/tanks_multisine.toml");
    let text_of = std::fs::read_to_string(&family).unwrap();
    let loud = dir.join("loud.toml");
    let louder = text_of.replace("rms = [0.4, 0.8]", "rms = 2.0");
    assert_ne!(louder, text_of, "the example's level moved");
    std::fs::write(&loud, louder).unwrap();
    let estimator = dir.join("e.tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(&family),
        "--compress",
        "arx:2,2",
        "--fit",
        "linear",
        "--sims",
        "200",
        "--calibrate",
        "200",
        "--validate",
        "100",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let shown = text(&twostage(&["inspect", path(&estimator)]).stdout);
    assert!(
        shown.contains("input family of its 300 held-out records")
            && shown.contains("pump: mean 2.2"),
        "{shown}"
    );
    let records = |model: &Path, name: &str| {
        let out_dir = dir.join(name);
        let out = twostage(&[
            "simulate",
            "--model-file",
            path(model),
            "--count",
            "3",
            "--seed",
            "5",
            "--out-dir",
            path(&out_dir),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        out_dir.join("data.csv")
    };
    let column = |file: &Path| {
        let out = twostage(&["estimate", "--estimator", path(&estimator), path(file)]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let table = text(&out.stdout);
        let mut lines = table.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let at = header.iter().position(|h| *h == "input_in_family").unwrap();
        let flags: Vec<String> = lines
            .map(|l| l.split(',').nth(at).unwrap().to_string())
            .collect();
        (flags, text(&out.stderr))
    };
    let (own, said) = column(&records(&family, "own"));
    assert_eq!(own, ["true", "true", "true"], "{said}");
    let (loud_flags, said) = column(&records(&loud, "loud"));
    assert_eq!(loud_flags, ["false", "false", "false"]);
    // One line for the three records, each named with its numbers.
    assert_eq!(said.matches("out of distribution").count(), 1, "{said}");
    assert!(
        said.contains(
            "experiments 0, 1, 2: out of distribution: their inputs lie outside the family \
             the estimator was trained on (experiment 0: input pump: RMS 2.000 above the \
             training records' 0.4"
        ) && said.contains("experiment 2: input pump: RMS 2.000"),
        "{said}"
    );
}

/// The first column after `experiment` of each row of an estimate CSV.
fn first_parameter(stdout: &str) -> Vec<f64> {
    stdout
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect()
}

/// A refined estimate is the likelihood's mean within the prior's box near
/// the best fit: a time constant that noisy records leave loose at its
/// prior's upper bound is pulled inside, where the best fit sits on the
/// bound; records that pin it down keep the best fit.
#[test]
fn a_refined_estimate_leaves_a_bound_the_record_does_not_pin_down() {
    let dir = scratch("equations-refined-bound");
    let states = "states = [{ name = \"x\", initial = 0, derivative = \"(u - x) / tau\" }]\n";
    let lag = lag_file(&dir, &format!("{states}outputs = {{ y = \"x\" }}\n"));
    let equations = std::fs::read_to_string(&lag).unwrap();
    let (mut refined_at_bound, mut pinned) = (0, 0);
    // Loose records at the bound; records that pin it down inside the box.
    for (noise, truth, loose) in [("1.0", "2.0", true), ("0.001", "1.25", false)] {
        let model = dir.join(format!("lag-{noise}.toml"));
        std::fs::write(
            &model,
            format!("{equations}\n[noise]\noutput_sd = {noise}\n"),
        )
        .unwrap();
        let estimator = dir.join(format!("lag-{noise}.tsest"));
        let out = twostage(&[
            "train",
            "--model-file",
            path(&model),
            "--compress",
            "arx:1,1",
            "--fit",
            "linear",
            "--sims",
            "200",
            "--validate",
            "0",
            "--calibrate",
            "200",
            "--quiet",
            "--out",
            path(&estimator),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let records = dir.join(format!("records-{noise}"));
        for i in 0..8 {
            let out = twostage(&[
                "simulate",
                "--model-file",
                path(&model),
                "--theta",
                truth,
                "--experiment",
                &i.to_string(),
                "--seed",
                "4",
                "--out",
                path(&records.with_extension(format!("{i}.csv"))),
            ]);
            assert!(out.status.success(), "{}", text(&out.stderr));
        }
        let files: Vec<String> = (0..8)
            .map(|i| path(&records.with_extension(format!("{i}.csv"))).to_string())
            .collect();
        let estimate = |extra: &[&str]| {
            let mut args = vec!["estimate", "--model-file", path(&model)];
            args.extend_from_slice(extra);
            args.extend(files.iter().map(String::as_str));
            let out = twostage(&args);
            assert!(out.status.success(), "{}", text(&out.stderr));
            first_parameter(&text(&out.stdout))
        };
        let best = estimate(&["--method", "oe", "--starts", "4"]);
        let refined = estimate(&["--estimator", path(&estimator), "--refine"]);
        for (b, r) in best.iter().zip(&refined) {
            assert!((0.5..=2.0).contains(r), "{r} outside the prior's box");
            if loose && *b >= 2.0 - 1e-9 {
                assert!(*r < 2.0 - 1e-3, "best fit {b} on the bound, refined {r}");
                refined_at_bound += 1;
            }
            if !loose {
                assert!(
                    (r - b).abs() < 1e-6 * b,
                    "pinned: best fit {b}, refined {r}"
                );
                pinned += 1;
            }
        }
    }
    assert!(
        refined_at_bound >= 1 && pinned == 8,
        "{refined_at_bound} at the bound"
    );
}
