"""duffing.toml's oscillator as a numpy simulator over protocol 2
(duffing_numpy.toml), vectorized over each batch: x'' = b u - c x' - k x
- k3 x^3, y = x + e, RK4 with four steps a sample, the input held between
samples. docs/real-data.md ("The best fit on the measured tanks") times
its refinement against scipy's. With COUNT_LOG set, each request appends
its number of points to that file."""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
from twostage_protocol import serve  # noqa: E402

SAMPLE_TIME = 0.0016384
NOISE_SD = 0.0002


def response(theta, u):
    c, k, k3, b = (theta[:, j][:, None] for j in range(4))
    x = np.zeros((theta.shape[0], 1))
    v = np.zeros_like(x)
    y = np.empty((theta.shape[0], u.shape[1]))
    h = SAMPLE_TIME / 4

    def acc(x, v, w):
        return b * w - c * v - k * x - k3 * x * x * x

    for t in range(u.shape[1]):
        y[:, t] = x[:, 0]
        w = u[:, t : t + 1]
        for _ in range(4):
            a1 = acc(x, v, w)
            x2, v2 = x + 0.5 * h * v, v + 0.5 * h * a1
            a2 = acc(x2, v2, w)
            x3, v3 = x + 0.5 * h * v2, v + 0.5 * h * a2
            a3 = acc(x3, v3, w)
            x4, v4 = x + h * v3, v + h * a3
            a4 = acc(x4, v4, w)
            x, v = x + h / 6 * (v + 2 * v2 + 2 * v3 + v4), v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return y


def batch(thetas, seeds, indices, noiseless=False, input=None):
    if os.environ.get("COUNT_LOG"):
        with open(os.environ["COUNT_LOG"], "a") as log:
            log.write("%d\n" % len(thetas))
    theta = np.asarray(thetas, dtype=float)
    u = np.repeat(np.asarray(input, dtype=float)[None, :, 0], theta.shape[0], axis=0)
    y = response(theta, u)
    if not noiseless:
        for j, (seed, index) in enumerate(zip(seeds, indices)):
            y[j] += NOISE_SD * np.random.default_rng([seed, index]).standard_normal(u.shape[1])
    return u[:, :, None], y[:, :, None]


if __name__ == "__main__":
    serve(batch=batch)
