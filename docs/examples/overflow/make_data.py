"""The records of the overflow example: the model itself at PLANT, with
AR(1) sensor noise (0.6) that the model's white noise does not describe.
Writes estimation.csv and validation.csv (pump,level; 1024 samples every
4 s, each on its own multisine) and truth.txt.

    python3 make_data.py [DIR]
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from overflow import SAMPLES, levels, multisine  # noqa: E402

PLANT = {"k": 1.0, "a1": 0.8, "a2": 0.7, "hmax": 8.0, "c": 0.5, "h10": 3.0, "h20": 6.0}


def record(seed, n=SAMPLES):
    rng = np.random.default_rng(seed)
    u = multisine(rng, n)
    theta = np.array([list(PLANT.values())])
    h = levels(theta, u[None, :])[0]
    e = np.zeros(n)
    white = 0.03 * rng.standard_normal(n)
    for t in range(1, n):
        e[t] = 0.6 * e[t - 1] + white[t]
    return u, h[:, 1] + e


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "."
    os.makedirs(out, exist_ok=True)
    for name, seed in (("estimation", 21), ("validation", 22)):
        u, y = record(seed)
        with open(os.path.join(out, name + ".csv"), "w") as f:
            f.write("pump,level\n")
            for a, b in zip(u, y):
                f.write("%r,%r\n" % (float(a), float(b)))
    with open(os.path.join(out, "truth.txt"), "w") as f:
        f.write(" ".join("%s=%r" % kv for kv in PLANT.items()) + "\n")


if __name__ == "__main__":
    main()
