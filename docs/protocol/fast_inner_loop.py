"""A simulator whose loop runs faster than its records (docs/protocol.md,
"A simulator faster than its records"): a first-order plant

    tau dx/dt = -x + k u,   y = x + e,   e ~ N(0, 0.01^2)

stepped at 1 kHz, its records sampled every 10 ms. A given input arrives
at the record's rate; each value is held over the ten inner steps of its
sample, as a digital-to-analogue converter holds it, and the output is
read at the record's instants only.
"""

import math
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from twostage_protocol import serve  # noqa: E402

RECORD_STEP = 0.01  # s: the model file's [signals] sample_time
INNER_STEPS = 10  # the loop's steps per record sample (1 kHz)
SAMPLES = 200


def simulate(theta, seed, index, noiseless=False, input=None):
    k, tau = theta
    rng = random.Random(seed * 1000003 + index)
    if input is None:
        # Its own design: a new level every 50 record samples.
        u = []
        while len(u) < SAMPLES:
            u += [rng.uniform(-1.0, 1.0)] * 50
        u = u[:SAMPLES]
    else:
        # At the record's rate: one value per record sample.
        u = [row[0] for row in input]
    # Exact for an input held over the inner step.
    decay = math.exp(-RECORD_STEP / INNER_STEPS / tau)
    x, y = 0.0, []
    for held in u:
        y.append(x)  # the record reads the plant at its own instants
        for _ in range(INNER_STEPS):
            x = decay * x + (1.0 - decay) * k * held
    if not noiseless:
        y = [v + 0.01 * rng.gauss(0.0, 1.0) for v in y]
    # The input goes back as it came: twostage compares it bit for bit.
    return [[v] for v in u], [[v] for v in y]


if __name__ == "__main__":
    serve(simulate)
