"""Training through a numpy simulator against the built-in model
(docs/performance.md): the benchmark's protocol function
(docs/protocol/benchmark_numpy.py) called in batches, the same sizes.

    python crates/python/bench/simulator_overhead.py [--sims 8000]
"""

import argparse
import importlib.util
import time
from pathlib import Path

import twostage

ROOT = Path(__file__).resolve().parents[3]

MODEL = (ROOT / "docs" / "protocol" / "benchmark_numpy.toml").read_text()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sims", type=int, default=8000)
    args = parser.parse_args()
    path = ROOT / "docs" / "protocol" / "benchmark_numpy.py"
    spec = importlib.util.spec_from_file_location("benchmark_numpy", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    sizes = dict(sims=args.sims, validate=1000, calibrate=1000, seed=1, progress=False)
    phases = []

    def timed(label, **kwargs):
        start = time.perf_counter()
        estimator = twostage.train(**kwargs, **sizes)
        seconds = time.perf_counter() - start
        rmse = estimator.validation["parameters"][0]["rmse"]
        phases.append((label, seconds, rmse))

    timed("built-in benchmark", model="benchmark")
    for batch in (16, 64, 256):
        timed("numpy, batches of %d" % batch, model_toml=MODEL, simulator=bench.batch,
              batch_size=batch)
    base = phases[0][1]
    for label, seconds, rmse in phases:
        print("%-24s %7.2f s  (%.2f x)  validation RMSE %.4f" % (label, seconds, seconds / base, rmse))


if __name__ == "__main__":
    main()
