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
