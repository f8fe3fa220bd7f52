"""An SIR epidemic served to twostage over the simulator protocol
(docs/protocol.md), in pure Python: no package needed.

    dS/dt = -beta S I,  dI/dt = beta S I - gamma I,  dR/dt = gamma I

from S = 0.99, I = 0.01, integrated with 100 Euler steps a day. The
measured output is the infected share every 3 days, with 5% multiplicative
noise drawn from (seed, index): experiment i of a chart is always the same.
It speaks protocol 2 (sir.toml says `protocol = 2`): asked for a
noise-free run, it returns the infected share itself, which `twostage
estimate --check` and `--refine` compare with a measured record.
"""

import os
import random
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
from twostage_protocol import serve  # noqa: E402

SAMPLES, DAYS_BETWEEN, STEPS_PER_DAY = 10, 3, 100


def infected(beta, gamma):
    s, i, out, dt = 0.99, 0.01, [], 1.0 / STEPS_PER_DAY
    for k in range(SAMPLES):
        if k > 0:
            for _ in range(DAYS_BETWEEN * STEPS_PER_DAY):
                new, gone = beta * s * i * dt, gamma * i * dt
                s, i = s - new, i + new - gone
        out.append(i)
    return out


def simulate(theta, seed, index, noiseless=False, input=None):
    beta, gamma = theta
    rng = random.Random(seed * 1000003 + index)
    noise = 0.0 if noiseless else 0.05
    y = [v * (1 + noise * rng.gauss(0, 1)) for v in infected(beta, gamma)]
    return [], [[v] for v in y]


if __name__ == "__main__":
    serve(simulate)
