"""Training from a numpy simulator: the protocol's batch function
(docs/protocol/benchmark_numpy.py) called in-process, against the same
function served to the command line and against the built-in model."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import twostage

ROOT = Path(__file__).resolve().parents[3]
CLI = os.environ.get("TWOSTAGE_CLI")


def _numpy_benchmark():
    path = ROOT / "docs" / "protocol" / "benchmark_numpy.py"
    spec = importlib.util.spec_from_file_location("benchmark_numpy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


BENCHMARK = _numpy_benchmark()

# The benchmark as a model file without a source: names, prior, signals,
# the paper's preset. The simulator comes from Python.
MODEL = (ROOT / "docs" / "protocol" / "benchmark_numpy.toml").read_text()

SMALL = dict(sims=400, validate=100, calibrate=100, seed=3, progress=False)


def test_the_cli_serving_the_same_function_trains_the_same_file(tmp_path):
    if not CLI:
        pytest.fail("TWOSTAGE_CLI is not set: run the suite with `cargo xtask test`")
    python_side = twostage.train(
        model_toml=MODEL, simulator=BENCHMARK.batch, batch_size=16, **SMALL
    )
    served = tmp_path / "served.toml"
    command = [sys.executable, str(ROOT / "docs" / "protocol" / "benchmark_numpy.py")]
    served.write_text(
        MODEL.replace(
            "[[parameter]]",
            "[source]\ncommand = %s\nbatch = 5\n\n[[parameter]]" % _toml_list(command),
            1,
        )
    )
    out = tmp_path / "cli.tsest"
    done = subprocess.run(
        [CLI, "train", "--model-file", str(served), "--sims", "400", "--validate", "100",
         "--calibrate", "100", "--seed", "3", "--out", str(out), "--quiet"],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    # Other batch sizes on both sides, the same records: the same bits.
    assert out.read_bytes() == python_side.to_bytes()


def _toml_list(items):
    return "[" + ", ".join('"%s"' % s.replace("\\", "\\\\") for s in items) + "]"


def test_a_numpy_simulator_trains_as_accurately_as_the_built_in_model():
    size = dict(sims=1500, validate=0, calibrate=0, seed=4, progress=False)
    from_numpy = twostage.train(model_toml=MODEL, simulator=BENCHMARK.batch, **size)
    built_in = twostage.train(model="benchmark", **size)
    # The same 1000 fresh records for both, from the numpy function.
    r = 1000
    rng = np.random.default_rng(99)
    theta = rng.uniform(-0.9, 0.9, size=(r, 1))
    u, y = BENCHMARK.batch(theta, np.full(r, 12345, dtype=np.uint64), np.arange(r, dtype=np.uint64))
    a = (from_numpy.estimate(u, y) - theta)[:, 0] ** 2
    b = (built_in.estimate(u, y) - theta)[:, 0] ** 2
    # The paired difference of squared errors, against its sampling error.
    d = a - b
    se = d.std(ddof=1) / np.sqrt(r)
    assert abs(d.mean()) < 4 * se + 1e-12, (a.mean(), b.mean(), se)
    assert np.sqrt(a.mean()) < 0.05


def test_progress_reports_every_stage():
    events = []
    twostage.train(
        model_toml=MODEL, simulator=BENCHMARK.batch, sims=200, validate=50, calibrate=0,
        progress=lambda event, stage, count: events.append((event, stage, count)),
    )
    begun = [(s, n) for e, s, n in events if e == "begin"]
    assert ("training", 200) in begun and ("validation", 50) in begun
    done = {}
    for event, stage, count in events:
        if event == "advance":
            done[stage] = done.get(stage, 0) + count
    assert done["training"] == 200 and done["validation"] == 50
    assert [e for e, s, _ in events if s == "training"][-1] == "end"


def _failing(message):
    def simulate(thetas, seeds, indices):
        raise RuntimeError(message)
    return simulate


@pytest.mark.parametrize(
    "simulator, message",
    [
        (_failing("the solver diverged"), r"RuntimeError: the solver diverged"),
        (lambda t, s, i: (np.zeros((len(t), 1000, 1)), np.zeros((len(t), 999, 1))),
         r"outputs have shape \[\d+, 999, 1\], expected \[\d+, 1000, 1\]"),
        (lambda t, s, i: (np.zeros((len(t), 1000, 1)), np.zeros((len(t), 1000, 1), np.float32)),
         r"outputs have dtype float32, not float64"),
        (lambda t, s, i: np.zeros((len(t), 1000, 1)),
         r"not the pair \(inputs \[b, N, 1\], outputs \[b, N, 1\]\)"),
    ],
)
def test_a_bad_simulator_is_named_with_its_fault(simulator, message):
    with pytest.raises(ValueError, match=message):
        twostage.train(model_toml=MODEL, simulator=simulator, sims=50, validate=0,
                       calibrate=0, progress=False)


def test_a_simulator_needs_a_model_file_without_a_source():
    with pytest.raises(ValueError, match="model file without"):
        twostage.train(model="benchmark", simulator=BENCHMARK.batch, progress=False)
    with pytest.raises(ValueError, match=r"model_toml, line 10, key `parameter.prior.dist`"):
        twostage.train(model_toml=MODEL.replace("uniform", "uniformly"),
                       simulator=BENCHMARK.batch, progress=False)


def _chart(m, seed):
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-0.9, 0.9, size=(m, 1))
    u, y = BENCHMARK.batch(theta, np.full(m, seed, dtype=np.uint64), np.arange(m, dtype=np.uint64))
    return theta, u, y


def test_a_chart_of_arrays_trains_as_the_cli_trains_on_its_files(tmp_path):
    if not CLI:
        pytest.fail("TWOSTAGE_CLI is not set: run the suite with `cargo xtask test`")
    theta, u, y = _chart(500, 8)
    model = tmp_path / "chart.toml"
    model.write_text(MODEL)
    from_arrays = twostage.train(model_file=model, chart=(theta, u, y), validate=100,
                                 calibrate=100, seed=2, progress=False)
    folder = tmp_path / "chart"
    folder.mkdir()
    for name, array in (("theta", theta), ("inputs", u), ("outputs", y)):
        np.save(folder / (name + ".npy"), array)
    out = tmp_path / "cli.tsest"
    done = subprocess.run(
        [CLI, "train", "--model-file", str(model), "--chart", str(folder), "--validate", "100",
         "--calibrate", "100", "--seed", "2", "--out", str(out), "--quiet"],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    # The folder itself: the CLI's file, bit for bit.
    from_folder = twostage.train(model_file=model, chart=folder, validate=100,
                                 calibrate=100, seed=2, progress=False)
    assert out.read_bytes() == from_folder.to_bytes()
    # The arrays: the same estimator, the chart named as arrays.
    cli_dict, arrays_dict = twostage.Estimator.load(out).to_dict(), from_arrays.to_dict()
    assert arrays_dict["training"].pop("sampling").startswith("the chart of 500 experiments given as arrays")
    cli_dict["training"].pop("sampling")
    assert arrays_dict == cli_dict
    assert from_arrays.validation["parameters"][0]["rmse"] < 0.1


def test_a_bad_chart_is_named():
    theta, u, y = _chart(50, 9)
    y[7, 3, 0] = np.nan
    with pytest.raises(ValueError, match=r"chart: outputs\[7, 3, 0\] = NaN is not a finite number"):
        twostage.train(model_toml=MODEL, chart=(theta, u, y), validate=10, calibrate=0,
                       progress=False)
    with pytest.raises(ValueError, match="chart outputs must be a float64"):
        twostage.train(model_toml=MODEL, chart=(theta, u, y.astype(np.float32)),
                       progress=False)
    # Shapes are the model's, as a chart folder's are.
    with pytest.raises(ValueError, match=r"chart: theta has shape \[50, 2\]: expected \[m, 1\]"):
        twostage.train(model_toml=MODEL, chart=(np.hstack([theta, theta]), u, y),
                       progress=False)
    with pytest.raises(ValueError, match="validate_chart is a folder or a tuple"):
        twostage.train(model_toml=MODEL, chart=(theta, u, y), validate_chart=[1, 2],
                       progress=False)
