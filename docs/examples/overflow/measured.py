"""overflow.py's two tanks as a model of the public cascaded-tanks
benchmark's measured records (docs/real-data.md, "The best fit on the
measured tanks"): the same equations, the level sensor saturating at
10 V as the benchmark's does, output noise 0.05 V. Served over protocol
2, vectorized over each batch. With COUNT_LOG set, each request appends
its number of points to that file, for counting requests.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "protocol"))
import overflow  # noqa: E402
from twostage_protocol import serve  # noqa: E402

NOISE_SD = 0.05
SENSOR_TOP = 10.0


def batch(thetas, seeds, indices, noiseless=False, input=None):
    if os.environ.get("COUNT_LOG"):
        with open(os.environ["COUNT_LOG"], "a") as log:
            log.write("%d\n" % len(thetas))
    u, level = overflow.batch(thetas, seeds, indices, noiseless=True, input=input)
    y = np.minimum(level, SENSOR_TOP)
    if not noiseless:
        n = u.shape[1]
        for j, (seed, index) in enumerate(zip(seeds, indices)):
            # The stream overflow.py draws from: its own input first, if any.
            rng = np.random.default_rng([seed, index])
            if input is None:
                overflow.multisine(rng, n)
            y[j, :, 0] += NOISE_SD * rng.standard_normal(n)
    return u, y


if __name__ == "__main__":
    serve(batch=batch)
