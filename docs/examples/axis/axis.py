"""A positioning axis under closed-loop control, the model an engineer
would write down, in a plain per-sample Python loop (about 10 ms a record)
served to twostage over protocol 2 (docs/protocol.md):

    m dv/dt = F - Fv v - Fc tanh(v / 0.01) - F0,   dx/dt = v
    F = sat_20N( 400 (r - x) - 40 v )               (a P-D position loop)
    position = x + e,   e ~ N(0, (2e-5 m)^2)

with the reference position r held between samples (every 10 ms), the
axis at rest at 0, and eight semi-implicit Euler steps per sample (the
loop runs at 800 Hz inside, the record at 100 Hz). Without a given input
it draws its own reference: a new level in [-0.05, 0.05] m every 2.5 s.
"""

import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
from twostage_protocol import serve  # noqa: E402

SAMPLES = 2500
SAMPLE_TIME = 0.01
SUBSTEPS = 8
NOISE_SD = 2e-5


def reference(rng, n):
    """Reference positions: a new level every 250 samples."""
    levels = rng.uniform(-0.05, 0.05, size=(n + 249) // 250)
    return np.repeat(levels, 250)[:n]


def position(theta, r):
    """Noise-free positions of the axis (m, Fv, Fc, F0) following r."""
    m, fv, fc, f0 = (float(v) for v in theta)
    dt = SAMPLE_TIME / SUBSTEPS
    x = v = 0.0
    out = [0.0] * len(r)
    for t, target in enumerate(r):
        out[t] = x
        for _ in range(SUBSTEPS):
            force = 400.0 * (target - x) - 40.0 * v
            force = 20.0 if force > 20.0 else (-20.0 if force < -20.0 else force)
            a = (force - fv * v - fc * math.tanh(v / 0.01) - f0) / m
            v += dt * a
            x += dt * v
    return out


def batch(thetas, seeds, indices, noiseless=False, input=None):
    b = len(thetas)
    # A given input sets the record's length (a longer validation record).
    n = SAMPLES if input is None else len(input)
    u = np.empty((b, n))
    y = np.empty((b, n))
    for j, (theta, seed, index) in enumerate(zip(thetas, seeds, indices)):
        rng = np.random.default_rng([seed, index])
        own = reference(rng, SAMPLES)
        noise = rng.standard_normal(n)
        u[j] = own if input is None else np.asarray(input, dtype=float)[:, 0]
        y[j] = position(theta, u[j].tolist())
        if not noiseless:
            y[j] += NOISE_SD * noise
    return u[:, :, None], y[:, :, None]


if __name__ == "__main__":
    serve(batch=batch)
