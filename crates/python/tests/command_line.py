"""The command line binary the suites compare the package with:
TWOSTAGE_CLI (``cargo xtask test`` sets it to the one it built)."""

import os
import subprocess

import pytest

CLI = os.environ.get("TWOSTAGE_CLI")


def cli(*args):
    """Run the command line; its standard output, or the test fails with
    its standard error."""
    if not CLI:
        pytest.fail(
            "TWOSTAGE_CLI is not set: run the suite with `cargo xtask test`, "
            "or point it at a built `twostage` binary"
        )
    done = subprocess.run([CLI, *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


def cli_refusal(*args):
    """Run the command line where it must refuse: its standard error's
    first line without the ``error: `` the command puts before it."""
    if not CLI:
        pytest.fail("TWOSTAGE_CLI is not set: run the suite with `cargo xtask test`")
    done = subprocess.run([CLI, *args], capture_output=True, text=True)
    assert done.returncode != 0, done.stdout
    first = done.stderr.splitlines()[0]
    assert first.startswith("error: "), done.stderr
    return first[len("error: "):]
