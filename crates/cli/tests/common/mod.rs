//! What every command-line test needs: run the binary, read its output,
//! get a clean scratch folder.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Run `twostage` with `args`.
pub fn twostage(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twostage"))
        .args(args)
        .output()
        .expect("the twostage binary runs")
}

/// Run `twostage` with `args`, which must succeed; its standard output.
#[allow(dead_code)]
pub fn ok(args: &[&str]) -> String {
    let out = twostage(args);
    assert!(out.status.success(), "{args:?}: {}", text(&out.stderr));
    text(&out.stdout)
}

/// Output bytes as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8(bytes.to_vec()).expect("the output is UTF-8")
}

/// An empty folder of the test's own under the target directory.
pub fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the target directory is writable");
    dir
}

/// A path as an argument.
pub fn path(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}

/// A small estimator of the model file `model` (`arx:2,2`, linear, 400
/// simulations, seed 3), written beside it: for tests whose estimates
/// only start a refinement or show a flag, not for accuracy.
#[allow(dead_code)]
pub fn train_small(model: &Path) -> PathBuf {
    let estimator = model.with_extension("tsest");
    let out = twostage(&[
        "train",
        "--model-file",
        path(model),
        "--compress",
        "arx:2,2",
        "--fit",
        "linear",
        "--sims",
        "400",
        "--calibrate",
        "200",
        "--validate",
        "200",
        "--seed",
        "3",
        "--quiet",
        "--out",
        path(&estimator),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    estimator
}

/// Each row of a table (`estimate`'s, say): its first cell and its
/// fields by column name (those that read as numbers).
#[allow(dead_code)]
pub fn rows(table: &str) -> Vec<(String, Vec<(String, f64)>)> {
    let mut lines = table.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    lines
        .map(|line| {
            let cells: Vec<&str> = line.split(',').collect();
            let fields = header
                .iter()
                .zip(&cells)
                .skip(1)
                .filter_map(|(name, cell)| Some((name.to_string(), cell.parse().ok()?)))
                .collect();
            (cells[0].to_string(), fields)
        })
        .collect()
}

/// The field `name` of a row of [`rows`].
#[allow(dead_code)]
pub fn field(row: &[(String, f64)], name: &str) -> f64 {
    row.iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no {name} in {row:?}"))
        .1
}

/// Experiment `i` of the model file `model` at `theta` (with its noise),
/// written beside it as `r{i}.csv`: its path.
#[allow(dead_code)]
pub fn simulate_beside(model: &Path, theta: &str, i: usize) -> String {
    let record = model.with_file_name(format!("r{i}.csv"));
    let out = twostage(&[
        "simulate",
        "--model-file",
        path(model),
        "--theta",
        theta,
        "--experiment",
        &i.to_string(),
        "--out",
        path(&record),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    path(&record).to_string()
}

/// The Python to run simulators with: `TWOSTAGE_PYTHON` (as `cargo xtask
/// test` sets it), else the environment it made, else python3.
#[allow(dead_code)]
pub fn python() -> String {
    std::env::var("TWOSTAGE_PYTHON").unwrap_or_else(|_| {
        let venv = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/venv/bin/python");
        if venv.exists() {
            venv.to_string_lossy().into_owned()
        } else {
            "python3".into()
        }
    })
}
