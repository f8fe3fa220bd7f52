"""Records of axis.py's model itself (its own noise): estimation.csv and
validation.csv (reference,position; 2500 samples every 10 ms), each on
its own reference steps, and truth.txt with the constants.

    python3 make_data.py [DIR]
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from axis import NOISE_SD, SAMPLES, position, reference  # noqa: E402

TRUTH = {"m": 2.3, "Fv": 4.2, "Fc": 1.7, "F0": 0.3}


def record(seed):
    rng = np.random.default_rng(seed)
    r = reference(rng, SAMPLES)
    y = np.array(position(list(TRUTH.values()), r.tolist()))
    return r, y + NOISE_SD * rng.standard_normal(SAMPLES)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "."
    os.makedirs(out, exist_ok=True)
    for name, seed in (("estimation", 21), ("validation", 22)):
        r, y = record(seed)
        with open(os.path.join(out, name + ".csv"), "w") as f:
            f.write("reference,position\n")
            for a, b in zip(r, y):
                f.write("%r,%r\n" % (float(a), float(b)))
    with open(os.path.join(out, "truth.txt"), "w") as f:
        f.write(" ".join("%s=%r" % kv for kv in TRUTH.items()) + "\n")


if __name__ == "__main__":
    main()
