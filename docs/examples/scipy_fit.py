"""The yardstick of docs/accuracy.md ("Refinement at the simulator's
pace"): a multi-start least-squares output-error fit with scipy, through
the same simulator module twostage runs (called in-process, no protocol),
the Jacobian by forward differences of all parameters in one batch call.

    python3 scipy_fit.py SIM.py ESTIMATION.csv VALIDATION.csv \\
        --lower L1,L2,.. --upper U1,U2,.. [--starts 10] [--seed 0]

The starts are drawn uniformly in the box (twostage's prior box of the
model, `twostage models --model-file`); the fit is bounded by it. Prints
the wall time, the best parameters and the RMS residual on both records.
"""

import argparse
import importlib.util
import time

import numpy as np
from scipy.optimize import least_squares


def load(path):
    spec = importlib.util.spec_from_file_location("sim", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    names = data.dtype.names
    return np.asarray(data[names[0]], dtype=float), np.asarray(data[names[1]], dtype=float)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("sim")
    p.add_argument("estimation")
    p.add_argument("validation")
    p.add_argument("--lower", required=True)
    p.add_argument("--upper", required=True)
    p.add_argument("--starts", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    sim = load(a.sim)
    lower = np.array([float(v) for v in a.lower.split(",")])
    upper = np.array([float(v) for v in a.upper.split(",")])
    u, y = read(a.estimation)
    scale = 1.0 / y.std()

    def response(thetas, u):
        n = len(thetas)
        _, out = sim.batch(thetas, [0] * n, list(range(n)), noiseless=True, input=u[:, None])
        return out[:, :, 0]

    def residuals(theta):
        return scale * (y - response([theta], u)[0])

    def jacobian(theta):
        steps = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(theta))
        points = [theta]
        for j in range(len(theta)):
            point = theta.copy()
            # Forward, or backward at the upper bound.
            point[j] = theta[j] + steps[j] if theta[j] + steps[j] <= upper[j] else theta[j] - steps[j]
            points.append(point)
        out = response(points, u)
        base = scale * (y - out[0])
        return np.stack(
            [(scale * (y - out[j + 1]) - base) / (points[j + 1][j] - theta[j]) for j in range(len(theta))],
            axis=1,
        )

    rng = np.random.default_rng(a.seed)
    started = time.time()
    best = None
    for _ in range(a.starts):
        start = rng.uniform(lower, upper)
        fit = least_squares(residuals, start, jac=jacobian, bounds=(lower, upper))
        if best is None or fit.cost < best.cost:
            best = fit
    elapsed = time.time() - started
    rms = np.sqrt(np.mean((y - response([best.x], u)[0]) ** 2))
    uv, yv = read(a.validation)
    rms_v = np.sqrt(np.mean((yv - response([best.x], uv)[0]) ** 2))
    print("wall %.1f s, %d starts" % (elapsed, a.starts))
    print("theta " + ",".join("%.6g" % v for v in best.x))
    print("estimation RMS %.6g, validation RMS %.6g" % (rms, rms_v))


if __name__ == "__main__":
    main()
