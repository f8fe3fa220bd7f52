"""Estimating a batch of benchmark records from Python against Rust
(docs/performance.md): the same records, the same estimator, the best
of five runs each.

    python crates/python/bench/batch_cost.py [--records 100000]

Needs the package installed (``pip install ./crates/python`` or
``maturin develop --release``) and builds the Rust side with cargo.
"""

import argparse
import importlib.util
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import twostage

ROOT = Path(__file__).resolve().parents[3]


def numpy_benchmark():
    path = ROOT / "docs" / "protocol" / "benchmark_numpy.py"
    spec = importlib.util.spec_from_file_location("benchmark_numpy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--records", type=int, default=100_000)
    args = parser.parse_args()
    b = args.records
    bench = numpy_benchmark()
    rng = np.random.default_rng(5)
    theta = rng.uniform(-0.9, 0.9, size=(b, 1))
    u = np.empty((b, 1000, 1))
    y = np.empty((b, 1000, 1))
    for start in range(0, b, 10_000):
        stop = min(b, start + 10_000)
        seeds = np.full(stop - start, 5, dtype=np.uint64)
        indices = np.arange(start, stop, dtype=np.uint64)
        u[start:stop], y[start:stop] = bench.batch(theta[start:stop], seeds, indices)
    estimator = twostage.train(model="benchmark", seed=1, progress=False)
    with tempfile.TemporaryDirectory() as scratch:
        path = os.path.join(scratch, "benchmark.tsest")
        estimator.save(path)
        chart = os.path.join(scratch, "chart")
        os.makedirs(chart)
        for name, array in (("theta", theta), ("inputs", u), ("outputs", y)):
            np.save(os.path.join(chart, name + ".npy"), array)
        rust = float(subprocess.run(
            ["cargo", "run", "--quiet", "--release", "-p", "twostage-benches",
             "--example", "batch_cost", "--", path, chart],
            cwd=ROOT, check=True, capture_output=True, text=True,
        ).stdout)
    python = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        estimates = estimator.estimate(u, y)
        python = min(python, time.perf_counter() - start)
    assert estimates.shape == (b, 1)
    print(
        "%d benchmark records (paper preset): Rust estimate_batch %.3f s (%.2f us per record), "
        "Python estimate %.3f s (%.2f us per record): %.3f times"
        % (b, rust, 1e6 * rust / b, python, 1e6 * python / b, python / rust)
    )


if __name__ == "__main__":
    main()
