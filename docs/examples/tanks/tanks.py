"""Two tanks in cascade, the model an engineer would write down, served to
twostage over protocol 2 (docs/protocol.md), vectorized over each batch:

    dh1/dt = k u - a1 sqrt(h1)
    dh2/dt = a1 sqrt(h1) - a2 sqrt(h2)
    level  = h2 + e,   e ~ N(0, 0.05^2)

with the pump voltage u held between samples (every 2 s), both tanks
starting at the level h0, and RK4 with four steps per sample. Without a
given input it draws its own: steps between 1 and 3.5 V every 40 s.
The plant behind docs/real-data.md's records is not this model (see
make_data.py): a model is never exact.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
from twostage_protocol import serve  # noqa: E402

SAMPLES = 400
SAMPLE_TIME = 2.0
NOISE_SD = 0.05


def steps(rng, n):
    """Pump voltages: a new level every 20 samples."""
    levels = rng.uniform(1.0, 3.5, size=(n + 19) // 20)
    return np.repeat(levels, 20)[:n]


def levels(theta, u, leak=0.0):
    """Noise-free h1, h2 for each row of theta (k, a1, a2, h0) and of u."""
    k, a1, a2, h0 = (theta[:, j][:, None] for j in range(4))
    h = np.concatenate([h0, h0], axis=1)
    out = np.empty((theta.shape[0], u.shape[1], 2))

    def rate(h, v):
        s1 = np.sqrt(np.maximum(h[:, 0:1], 0.0))
        s2 = np.sqrt(np.maximum(h[:, 1:2], 0.0))
        return np.concatenate([k * v - a1 * s1, a1 * s1 - a2 * s2 - leak * h[:, 1:2]], axis=1)

    dt = SAMPLE_TIME / 4
    for t in range(u.shape[1]):
        out[:, t] = h
        v = u[:, t : t + 1]
        for _ in range(4):
            r1 = rate(h, v)
            r2 = rate(h + 0.5 * dt * r1, v)
            r3 = rate(h + 0.5 * dt * r2, v)
            r4 = rate(h + dt * r3, v)
            h = h + dt / 6 * (r1 + 2 * r2 + 2 * r3 + r4)
    return out


def batch(thetas, seeds, indices, noiseless=False, input=None):
    theta = np.asarray(thetas, dtype=float)
    b = theta.shape[0]
    # A given input sets the record's length (a longer validation record).
    n = SAMPLES if input is None else len(input)
    u = np.empty((b, n))
    noise = np.empty((b, n))
    for j, (seed, index) in enumerate(zip(seeds, indices)):
        rng = np.random.default_rng([seed, index])
        own = steps(rng, SAMPLES)
        if input is None:
            u[j] = own
        noise[j] = rng.standard_normal(n)
    if input is not None:
        u[:] = np.asarray(input, dtype=float)[:, 0]
    y = levels(theta, u)[:, :, 1]
    if not noiseless:
        y = y + NOISE_SD * noise
    return u[:, :, None], y[:, :, None]


if __name__ == "__main__":
    serve(batch=batch)
