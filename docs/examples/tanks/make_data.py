"""The 'measured' records of docs/real-data.md: a two-tank plant that is
not tanks.py's model. Its lower tank also leaks (a loss proportional to
its level, which the model lacks), its sensor noise is coloured (AR(1),
0.7) rather than white, and its upper tank overflows at 30. It writes
estimation.csv and validation.csv (pump,level; 400 samples every 2 s),
each on its own pump steps, validation_long.csv (1600 samples: a record
four times the estimation window, which the model simulates at its own
length), validation_refilled.csv (the validation record's pump steps,
the tanks filled to 8 instead of 4 at its start: a record's own initial
level, docs/real-data.md) and truth.txt with the plant's constants.

    python3 make_data.py [DIR]
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from tanks import SAMPLES, levels, steps  # noqa: E402

PLANT = {"k": 1.2, "a1": 0.9, "a2": 0.8, "h0": 4.0, "leak": 0.02}


def record(seed, n=SAMPLES, h0=PLANT["h0"]):
    rng = np.random.default_rng(seed)
    u = steps(rng, n)
    theta = np.array([[PLANT["k"], PLANT["a1"], PLANT["a2"], h0]])
    h = levels(theta, u[None, :], leak=PLANT["leak"])[0]
    h = np.minimum(h, 30.0)
    e = np.zeros(n)
    white = 0.05 * rng.standard_normal(n)
    for t in range(1, n):
        e[t] = 0.7 * e[t - 1] + white[t]
    return u, h[:, 1] + e


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "."
    os.makedirs(out, exist_ok=True)
    for name, seed, n, h0 in (
        ("estimation", 11, SAMPLES, PLANT["h0"]),
        ("validation", 12, SAMPLES, PLANT["h0"]),
        ("validation_long", 13, 4 * SAMPLES, PLANT["h0"]),
        ("validation_refilled", 12, SAMPLES, 8.0),
    ):
        u, y = record(seed, n, h0)
        with open(os.path.join(out, name + ".csv"), "w") as f:
            f.write("pump,level\n")
            for a, b in zip(u, y):
                f.write("%r,%r\n" % (float(a), float(b)))
    with open(os.path.join(out, "truth.txt"), "w") as f:
        f.write(" ".join("%s=%r" % kv for kv in PLANT.items()) + "\n")


if __name__ == "__main__":
    main()
