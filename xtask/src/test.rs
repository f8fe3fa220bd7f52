//! `cargo xtask test`: the project's whole test suite on a fresh machine.
//! Some tests drive real external programs (the numpy reference simulator
//! of docs/protocol/), and the Python package has its own pytest suite, so
//! this sets up a Python virtual environment under target/, runs
//! `cargo test --workspace` with `TWOSTAGE_PYTHON` pointing at it, then
//! builds the package into it with maturin and runs pytest against the
//! command line the cargo tests built.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// The Python packages the tests use, pinned.
const PYTHON_PACKAGES: &[&str] = &["numpy==2.3.5", "maturin==1.9.0", "pytest==9.2.0"];

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
    python_package(&root, &python)
}

/// Build crates/python into the environment (`maturin develop`, the test
/// profile's code) and run its pytest suite, doctests included, against
/// the command line binary `cargo test` built.
fn python_package(root: &Path, python: &Path) -> Result<()> {
    let venv = root.join("target/venv");
    let status = Command::new(venv.join("bin/maturin"))
        .current_dir(root)
        .args([
            "develop",
            "--quiet",
            "--manifest-path",
            "crates/python/Cargo.toml",
        ])
        .env("VIRTUAL_ENV", &venv)
        .status()
        .context("running maturin develop")?;
    if !status.success() {
        bail!("maturin develop (the Python package) failed ({status})");
    }
    let status = Command::new(python)
        .current_dir(root)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "crates/python/tests",
            "--doctest-modules",
            "crates/python/python/twostage",
        ])
        .env("TWOSTAGE_CLI", root.join("target/debug/twostage"))
        .status()
        .context("running pytest")?;
    if !status.success() {
        bail!("pytest (the Python package) failed ({status})");
    }
    Ok(())
}

/// target/venv with the packages, created once; its python.
fn python_environment(root: &Path) -> Result<PathBuf> {
    let venv = root.join("target/venv");
    let python = venv.join("bin/python");
    let ready = |python: &Path| {
        Command::new(python)
            .args(["-c", "import numpy, pytest, maturin"])
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
