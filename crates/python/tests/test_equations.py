"""A model written as equations in its model file (decision 043) trains
from Python through either door (the file, or its text), and the
estimator it makes estimates records that the equations did not make:
sir.py's, the Python simulator the equations were written from."""

import importlib.util
from pathlib import Path

import numpy as np

import twostage

ROOT = Path(__file__).resolve().parents[3]
SIR = ROOT / "docs" / "examples" / "sir"


def _sir_py():
    spec = importlib.util.spec_from_file_location("sir", SIR / "sir.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_an_equations_model_trains_from_python_and_estimates_another_simulators_records():
    size = dict(sims=1500, validate=200, calibrate=200, seed=5, progress=False)
    path = SIR / "sir_equations.toml"
    from_file = twostage.train(model_file=path, **size)
    from_text = twostage.train(model_toml=path.read_text(), **size)
    # The same seed through either door: the same estimator.
    thetas = np.array([[0.3, 0.1], [0.5, 0.2], [0.8, 0.15], [0.45, 0.08]])
    sir = _sir_py()
    y = np.array([[[v] for v in sir.infected(b, g)] for b, g in thetas])
    a = from_file.estimate(None, y)
    b = from_text.estimate(None, y)
    np.testing.assert_array_equal(a, b)
    # sir.py's noise-free records, estimated within a few hundredths
    # (the estimator's validation RMSE is about 0.02 for both rates).
    assert np.abs(a - thetas).max() < 0.08, (a, thetas)
