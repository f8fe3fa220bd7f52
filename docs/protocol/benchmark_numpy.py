"""The paper's benchmark, eq. (5), written in numpy and served to twostage
through the protocol, vectorized over each batch:

    x1(k+1) = x1(k) / 2 + u(k) + v11(k)
    x2(k+1) = (1 - theta^2) sin(50 theta^2) x1(k) - theta x2(k) + theta / (1 + theta^2) u(k) + v12(k)
    y(k)    = x2(k) + v2(k)

with u, v11, v12 ~ N(0, 1) and v2 ~ N(0, 0.1), x(0) = 0. Each experiment
draws from numpy's generator seeded by [seed, index], so experiment i of a
chart is the same whatever the batch it comes in. Served with protocol 2
(`protocol = 2` under [source]) it also runs without noise and on given
inputs, one for the batch or one per experiment.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from twostage_protocol import serve  # noqa: E402

N_SAMPLES = 1000


def batch(thetas, seeds, indices, noiseless=False, input=None):
    theta = np.asarray(thetas, dtype=float)[:, 0]
    b = theta.size
    # A given input sets the record's length (a longer validation record,
    # say); the model's own input is N_SAMPLES long. One input serves the
    # whole batch ([N][1]) or each experiment has its own ([b][N][1]).
    given = None if input is None else np.asarray(input, dtype=float)[..., 0]
    n = N_SAMPLES if given is None else given.shape[-1]
    u = np.empty((b, n))
    noise = np.empty((b, 3, n))
    for j, (seed, index) in enumerate(zip(seeds, indices)):
        rng = np.random.default_rng([seed, index])
        own = rng.standard_normal(N_SAMPLES)
        if input is None:
            u[j] = own
        noise[j] = rng.standard_normal((3, n))
    if given is not None:
        u[:] = given
    if noiseless:
        noise[:] = 0.0
    a = (1 - theta**2) * np.sin(50 * theta**2)
    c = theta / (1 + theta**2)
    x1 = np.zeros(b)
    x2 = np.zeros(b)
    y = np.empty((b, n))
    for k in range(n):
        y[:, k] = x2 + np.sqrt(0.1) * noise[:, 2, k]
        x1, x2 = (
            0.5 * x1 + u[:, k] + noise[:, 0, k],
            a * x1 - theta * x2 + c * u[:, k] + noise[:, 1, k],
        )
    return u[:, :, None], y[:, :, None]


if __name__ == "__main__":
    serve(batch=batch)
