"""The predator-prey (Lotka-Volterra) example of docs/accuracy.md, in numpy:
the model, a chart writer in the .npy layout of `twostage train --chart`,
and a reference posterior mean by importance sampling.

    python3 lv.py chart OUT [M] [SEED]         # OUT/theta.npy, OUT/outputs.npy
    python3 lv.py reference CHART OUT.npy [K]  # posterior means of CHART's records
    python3 lv.py csv CHART OUT.csv            # CHART's records for `twostage estimate`
    python3 lv.py score REF.npy EST.csv        # mean |estimate - mean| / sd

Prey x and predators y: dx/dt = a x - b x y, dy/dt = c x y - d y, from
x(0) = 20, y(0) = 10, sampled every 1.5 time units (10 samples of each,
the first at t = 1.5), RK4 with step 0.01; observed with log-normal noise
(sd 0.1 of the logarithm). The four rates have log-normal priors, so the
populations span orders of magnitude.
"""

import os
import sys

import numpy as np

NAMES = ("a", "b", "c", "d")
# ln-medians and ln-sds of the rates' log-normal priors (lv.toml says the same).
MU = np.log(np.array([0.8, 0.05, 0.05, 0.8]))
SIGMA = np.array([0.3, 0.3, 0.3, 0.3])
X0, Y0 = 20.0, 10.0
SAMPLES, EVERY, DT = 10, 1.5, 0.01
NOISE = 0.1


def prior(rng, m):
    return np.exp(MU + SIGMA * rng.standard_normal((m, 4)))


def populations(theta):
    """Noise-free prey and predators [m, SAMPLES, 2] at the sample times."""
    a, b, c, d = (theta[:, j] for j in range(4))
    x = np.full(len(theta), X0)
    y = np.full(len(theta), Y0)

    def f(x, y):
        return a * x - b * x * y, c * x * y - d * y

    out = np.empty((len(theta), SAMPLES, 2))
    steps = int(round(EVERY / DT))
    for k in range(SAMPLES):
        for _ in range(steps):
            k1 = f(x, y)
            k2 = f(x + 0.5 * DT * k1[0], y + 0.5 * DT * k1[1])
            k3 = f(x + 0.5 * DT * k2[0], y + 0.5 * DT * k2[1])
            k4 = f(x + DT * k3[0], y + DT * k3[1])
            x = x + DT / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            y = y + DT / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            # The populations stay positive; RK4 may undershoot a collapse.
            x, y = np.maximum(x, 1e-9), np.maximum(y, 1e-9)
        out[:, k, 0], out[:, k, 1] = x, y
    return out


def chart(m, seed, block=20000):
    rng = np.random.default_rng(seed)
    theta = prior(rng, m)
    clean = np.concatenate([populations(theta[i:i + block]) for i in range(0, m, block)])
    return theta, clean * np.exp(NOISE * rng.standard_normal(clean.shape))


def log_likelihood(observed, clean):
    """[n_obs, n_sims] log-likelihoods of observed [n_obs, S, 2] records
    under noise-free simulations clean [n_sims, S, 2]."""
    lo, lc = np.log(observed), np.log(clean)
    sq = (lo[:, None] - lc[None]) ** 2
    return -sq.sum(axis=(2, 3)) / (2 * NOISE**2)


def reference(observed, k, seed):
    """Posterior means and sds of the rates for each observed record: a
    first importance-sampling round from the prior, then one from a
    Gaussian (in log-rates) fitted to each record's first-round posterior,
    widened 1.5 times, with prior / proposal weights. Returns means, sds and
    the second round's effective sample sizes."""
    rng = np.random.default_rng(seed)
    theta = prior(rng, k)
    clean = np.concatenate([populations(theta[j:j + 20000]) for j in range(0, k, 20000)])
    means, sds, ess = [], [], []
    for i in range(len(observed)):
        w = log_likelihood(observed[i:i + 1], clean)[0]
        p = np.exp(w - w.max())
        p /= p.sum()
        z = np.log(theta)
        mean = p @ z
        cov = ((z - mean).T * p) @ (z - mean) + 1e-6 * np.eye(4)
        chol = np.linalg.cholesky(2.25 * cov)
        zs = mean + rng.standard_normal((k // 4, 4)) @ chol.T
        ts = np.exp(zs)
        log_prior = -0.5 * (((zs - MU) / SIGMA) ** 2).sum(1)
        dev = np.linalg.solve(chol, (zs - mean).T)
        log_proposal = -0.5 * (dev**2).sum(0)
        lw = log_likelihood(observed[i:i + 1], populations(ts))[0] + log_prior - log_proposal
        q = np.exp(lw - lw.max())
        q /= q.sum()
        m1 = q @ ts
        means.append(m1)
        sds.append(np.sqrt(q @ (ts - m1) ** 2))
        ess.append(1.0 / (q**2).sum())
    return np.array(means), np.array(sds), np.array(ess)


def main():
    command = sys.argv[1]
    if command == "chart":
        target = sys.argv[2]
        m = int(sys.argv[3]) if len(sys.argv) > 3 else 100000
        seed = int(sys.argv[4]) if len(sys.argv) > 4 else 1
        theta, outputs = chart(m, seed)
        os.makedirs(target, exist_ok=True)
        np.save(os.path.join(target, "theta.npy"), theta)
        np.save(os.path.join(target, "outputs.npy"), outputs)
    elif command == "reference":
        folder, out = sys.argv[2], sys.argv[3]
        k = int(sys.argv[4]) if len(sys.argv) > 4 else 200000
        observed = np.load(os.path.join(folder, "outputs.npy"))
        means, sds, ess = reference(observed, k, 12345)
        np.save(out, np.stack([means, sds]))
        np.save(ess_path(out), ess)
        print("effective sample sizes: min %.0f, median %.0f" % (ess.min(), np.median(ess)))
    elif command == "csv":
        outputs = np.load(os.path.join(sys.argv[2], "outputs.npy"))
        with open(sys.argv[3], "w") as out:
            out.write("experiment,prey,predators\n")
            for i, record in enumerate(outputs):
                for x, y in record:
                    out.write("%d,%r,%r\n" % (i, float(x), float(y)))
    elif command == "score":
        means, sds = np.load(sys.argv[2])
        estimates = read_estimates(sys.argv[3], len(means))
        # A reference whose importance weights collapsed on a few draws is
        # no reference: such records are left out, and counted.
        kept = np.ones(len(means), dtype=bool)
        if os.path.exists(ess_path(sys.argv[2])):
            kept = np.load(ess_path(sys.argv[2])) >= MIN_ESS
        z = (np.abs(estimates - means) / sds)[kept]
        print("%d records (%d left out: effective sample size below %d): mean |z| %.3f; "
              "per rate %s" % (kept.sum(), (~kept).sum(), MIN_ESS, z.mean(),
                               " ".join("%s %.3f" % (n, v) for n, v in zip(NAMES, z.mean(0)))))
    else:
        sys.exit(__doc__)


# The smallest effective sample size of a record's reference for it to be
# scored against.
MIN_ESS = 100


def ess_path(reference):
    """Where the reference's effective sample sizes are kept."""
    return reference[:-4] + "-ess.npy" if reference.endswith(".npy") else reference + "-ess.npy"


def read_estimates(path, count):
    """The rates of `twostage estimate`'s CSV, one row per record in order
    of `experiment` (0 to count - 1)."""
    with open(path) as f:
        header = f.readline().strip().split(",")
        columns = [header.index(n) for n in NAMES]
        key = header.index("experiment")
        rows = {}
        for line in f:
            cells = line.strip().split(",")
            rows[int(cells[key])] = [float(cells[j]) for j in columns]
    missing = [i for i in range(count) if i not in rows]
    if missing:
        sys.exit("%s has no estimate for records %s" % (path, missing[:10]))
    return np.array([rows[i] for i in range(count)])


if __name__ == "__main__":
    main()
