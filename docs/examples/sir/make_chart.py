"""A chart of the SIR model simulated in numpy, written in the layout
`twostage train --chart` reads: OUT/truth.csv (experiment,beta,gamma) and
OUT/data.csv (experiment,I, one row per sample).

    python3 make_chart.py OUT [M] [SEED]
"""

import os
import sys

import numpy as np

SAMPLES, DAYS_BETWEEN, STEPS_PER_DAY = 10, 3, 100


def chart(m, seed):
    rng = np.random.default_rng(seed)
    beta = np.exp(rng.normal(-0.916, 0.5, m))
    gamma = rng.uniform(0.05, 0.3, m)
    s, i, dt = np.full(m, 0.99), np.full(m, 0.01), 1.0 / STEPS_PER_DAY
    out = np.empty((m, SAMPLES))
    for k in range(SAMPLES):
        if k > 0:
            for _ in range(DAYS_BETWEEN * STEPS_PER_DAY):
                new, gone = beta * s * i * dt, gamma * i * dt
                s, i = s - new, i + new - gone
        out[:, k] = i
    out *= 1 + 0.05 * rng.standard_normal(out.shape)
    return np.column_stack([beta, gamma]), out


def main():
    target = sys.argv[1]
    m = int(sys.argv[2]) if len(sys.argv) > 2 else 4000
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    theta, infected = chart(m, seed)
    os.makedirs(target, exist_ok=True)
    ids = np.arange(m)
    np.savetxt(os.path.join(target, "truth.csv"), np.column_stack([ids, theta]),
               delimiter=",", header="experiment,beta,gamma", comments="", fmt=["%d", "%.17g", "%.17g"])
    rows = np.column_stack([np.repeat(ids, SAMPLES), infected.reshape(-1)])
    np.savetxt(os.path.join(target, "data.csv"), rows,
               delimiter=",", header="experiment,I", comments="", fmt=["%d", "%.17g"])


if __name__ == "__main__":
    main()
