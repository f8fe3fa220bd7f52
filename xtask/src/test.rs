//! `cargo xtask test`: the project's whole test suite on a fresh machine.
//! Some tests drive real external programs (the numpy reference simulator
//! of docs/protocol/), so this sets up what they need in the checkout,
//! a Python virtual environment under target/, then runs
//! `cargo test --workspace` with `TWOSTAGE_PYTHON` pointing at it.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// The Python packages the tests import, pinned.
const PYTHON_PACKAGES: &[&str] = &["numpy==2.3.5"];

/// Run the suite, passing `args` on to `cargo test`.
pub fn run(args: &[String]) -> Result<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .context("xtask lives in the workspace")?
        .to_path_buf();
    let python = python_environment(&root)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .args(["test", "--workspace"])
        .args(args)
        .env("TWOSTAGE_PYTHON", &python)
        .status()
        .context("running cargo test")?;
    if !status.success() {
        bail!("cargo test --workspace failed ({status})");
    }
    Ok(())
}

/// target/venv with the packages, created once; its python.
fn python_environment(root: &Path) -> Result<PathBuf> {
    let venv = root.join("target/venv");
    let python = venv.join("bin/python");
    let ready = |python: &Path| {
        Command::new(python)
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if ready(&python) {
        return Ok(python);
    }
    eprintln!(
        "setting up {} for the tests ({})",
        venv.display(),
        PYTHON_PACKAGES.join(", ")
    );
    let base = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let status = Command::new(&base)
        .args(["-m", "venv"])
        .arg(&venv)
        .status()
        .with_context(|| format!("running {base} -m venv (install Python 3.9 or later)"))?;
    if !status.success() {
        bail!("{base} -m venv {} failed ({status})", venv.display());
    }
    let status = Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(PYTHON_PACKAGES)
        .status()
        .context("running pip")?;
    if !status.success() || !ready(&python) {
        bail!(
            "pip could not install {} into {}",
            PYTHON_PACKAGES.join(", "),
            venv.display()
        );
    }
    Ok(python)
}
