"""Two tanks in cascade whose upper tank overflows into the lower one, a
7-parameter model served over protocol 2 (docs/protocol.md), vectorized
over each batch: the second example of a refinement through a numpy
simulator (docs/accuracy.md, "One best fit, three training seeds").

    dh1/dt = k u - a1 sqrt(h1) - s (h1 - hmax)+
    dh2/dt = a1 sqrt(h1) + c s (h1 - hmax)+ - a2 sqrt(h2)
    level  = h2 + e,   e ~ N(0, 0.03^2)

with s = 2 per second (the overflow drains fast), the pump voltage u held
between samples (every 4 s), the tanks starting at h10 and h20, and RK4
with four steps per sample. Its input, given or its own, is a
random-phase multisine over the lowest 40 of 512 frequencies, 1024
samples.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
from twostage_protocol import serve  # noqa: E402

SAMPLES = 1024
SAMPLE_TIME = 4.0
NOISE_SD = 0.03
OVERFLOW_RATE = 2.0


def multisine(rng, n):
    """Pump voltages around 2.5 V: a random-phase multisine of RMS 0.8 V."""
    t = np.arange(n)
    phases = rng.uniform(0.0, 2.0 * np.pi, size=40)
    u = sum(np.cos(2.0 * np.pi * (f + 1) * t / n + p) for f, p in enumerate(phases))
    return 2.5 + 0.8 * u / u.std()


def levels(theta, u):
    """Noise-free h1, h2 for each row of theta (k, a1, a2, hmax, c, h10,
    h20) and of u."""
    k, a1, a2, hmax, c, h10, h20 = (theta[:, j][:, None] for j in range(7))
    h = np.concatenate([h10, h20], axis=1)
    out = np.empty((theta.shape[0], u.shape[1], 2))

    def rate(h, v):
        s1 = np.sqrt(np.maximum(h[:, 0:1], 0.0))
        s2 = np.sqrt(np.maximum(h[:, 1:2], 0.0))
        over = OVERFLOW_RATE * np.maximum(h[:, 0:1] - hmax, 0.0)
        return np.concatenate([k * v - a1 * s1 - over, a1 * s1 + c * over - a2 * s2], axis=1)

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
    n = SAMPLES if input is None else len(input)
    u = np.empty((b, n))
    noise = np.empty((b, n))
    for j, (seed, index) in enumerate(zip(seeds, indices)):
        rng = np.random.default_rng([seed, index])
        if input is None:
            u[j] = multisine(rng, n)
        noise[j] = rng.standard_normal(n)
    if input is not None:
        u[:] = np.asarray(input, dtype=float)[:, 0]
    y = levels(theta, u)[:, :, 1]
    if not noiseless:
        y = y + NOISE_SD * noise
    return u[:, :, None], y[:, :, None]


if __name__ == "__main__":
    serve(batch=batch)
