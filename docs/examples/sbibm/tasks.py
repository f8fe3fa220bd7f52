"""sbibm's SIR and Lotka-Volterra tasks (Lueckmann et al. 2021, the
sbibm package's `sir` and `lotka_volterra`), simulated in numpy, with
reference posteriors drawn by rejection sampling on the tasks'
likelihoods. Written for docs/accuracy.md's posterior scores (issue 71).

    python3 tasks.py chart TASK OUT [M] [SEED]   # OUT/theta.npy, OUT/outputs.npy
    python3 tasks.py observations TASK OUT [SEED] # 10 observations, the chart layout
    python3 tasks.py reference TASK OBS OUT.csv   # 10,000 exact draws of each
    python3 tasks.py grid OBS REF.csv             # SIR: the draws against a grid's moments
    python3 tasks.py csv OBS OUT.csv              # the records for `twostage estimate`
    python3 tasks.py check TASK                   # the integrator against scipy's
    python3 tasks.py serve TASK                   # the simulator protocol (docs/protocol.md)

TASK is `sir` or `lv`. The tasks as sbibm defines them:

- SIR: S, I, R of a population of 10^6 from I = 1, dS/dt = -b S I / N,
  dI/dt = b S I / N - g I, 160 days; I on days 0, 17, ..., 153 observed
  as Binomial(1000, I / N). Priors: b log-normal (ln 0.4, 0.5), g
  log-normal (ln 0.125, 0.2).
- Lotka-Volterra: prey x and predators y from (30, 1), dx/dt = a x - b x
  y, dy/dt = -c y + d x y, sampled at t = 0, 2.1, ..., 18.9 (10 each),
  observed log-normally with sd 0.1 of the logarithm of the population
  clamped to [1e-10, 1e4]. Priors: log-normal, ln-medians (-0.125, -3,
  -0.125, -3), ln-sd 0.5 each.

sbibm integrates with Julia's adaptive solvers; here a fixed-step RK4
(SIR on the shares S/N, I/N; Lotka-Volterra on the populations'
logarithms, whose right-hand side stays smooth as a population collapses)
whose error `check` measures against scipy's DOP853. The references use
the same integrator as the charts: the posterior is the one of this
simulator.

Reference draws: the maximum of the posterior (in the parameters'
logarithms) from the true parameters and the best of a prior batch, its
Laplace covariance, a Student-t proposal (5 degrees of freedom, the
covariance widened 1.5 times in sd) moved to its weighted draws' moments
until the weights are even, and rejection sampling against 1.2 times the
largest weight seen, as sbibm's own references are drawn (its proposal
is a flow fitted to slice-sampling draws). `grid` draws SIR's posterior
from a 2-D grid instead, to check the rejection sampler against.
"""

import os
import sys

import numpy as np

OBSERVATIONS, DRAWS = 10, 10_000


class Sir:
    names = ("beta", "gamma")
    outputs = ("I",)
    mu = np.log(np.array([0.4, 0.125]))
    sigma = np.array([0.5, 0.2])
    population, trials, dt = 1e6, 1000, 0.05
    days = np.arange(10) * 17.0

    def clean(self, theta):
        """Noise-free infected shares [m, 10, 1]."""
        b, g = theta[:, 0], theta[:, 1]
        i = np.full(len(theta), 1.0 / self.population)
        s = 1.0 - i

        def f(s, i):
            new = b * s * i
            return -new, new - g * i

        out = np.empty((len(theta), 10, 1))
        out[:, 0, 0] = i
        steps = int(round(17.0 / self.dt))
        h = self.dt
        for k in range(1, 10):
            for _ in range(steps):
                k1 = f(s, i)
                k2 = f(s + 0.5 * h * k1[0], i + 0.5 * h * k1[1])
                k3 = f(s + 0.5 * h * k2[0], i + 0.5 * h * k2[1])
                k4 = f(s + h * k3[0], i + h * k3[1])
                s = s + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
                i = i + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            out[:, k, 0] = i
        return out

    def observe(self, clean, rng):
        return rng.binomial(self.trials, np.clip(clean, 0.0, 1.0)).astype(float)

    def log_likelihood(self, observed, clean):
        """Log-likelihood (up to a constant) of one observed record under
        each of the noise-free records `clean`."""
        p = np.clip(clean, 1e-300, 1.0 - 1e-16)
        n = self.trials
        return (observed * np.log(p) + (n - observed) * np.log1p(-p)).sum(axis=(1, 2))

    def rhs(self, theta):
        b, g = theta
        n = self.population
        return lambda t, u: [-b * u[0] * u[1] / n, b * u[0] * u[1] / n - g * u[1]]

    def exact(self, theta):
        from scipy.integrate import solve_ivp

        n = self.population
        sol = solve_ivp(self.rhs(theta), (0, self.days[-1]), [n - 1.0, 1.0],
                        method="DOP853", rtol=1e-11, atol=1e-9, t_eval=self.days)
        return sol.y[1][:, None] / n


class LotkaVolterra:
    names = ("alpha", "beta", "gamma", "delta")
    outputs = ("prey", "predators")
    mu = np.array([-0.125, -3.0, -0.125, -3.0])
    sigma = np.full(4, 0.5)
    dt = 0.005
    times = np.arange(10) * 2.1
    noise = 0.1

    def clean(self, theta):
        """Noise-free populations [m, 10, 2], from their logarithms."""
        a, b, c, d = (theta[:, j] for j in range(4))
        u = np.full(len(theta), np.log(30.0))
        v = np.zeros(len(theta))

        def f(u, v):
            # Clamped exponents keep a diverging record finite; it is then
            # outside the observations' clamp anyway.
            return a - b * np.exp(np.minimum(v, 50.0)), d * np.exp(np.minimum(u, 50.0)) - c

        out = np.empty((len(theta), 10, 2))
        out[:, 0, 0], out[:, 0, 1] = 30.0, 1.0
        steps = int(round(2.1 / self.dt))
        h = self.dt
        for k in range(1, 10):
            for _ in range(steps):
                k1 = f(u, v)
                k2 = f(u + 0.5 * h * k1[0], v + 0.5 * h * k1[1])
                k3 = f(u + 0.5 * h * k2[0], v + 0.5 * h * k2[1])
                k4 = f(u + h * k3[0], v + h * k3[1])
                u = u + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
                v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            out[:, k, 0], out[:, k, 1] = np.exp(np.minimum(u, 700)), np.exp(np.minimum(v, 700))
        return out

    def observe(self, clean, rng):
        return np.exp(np.log(np.clip(clean, 1e-10, 1e4)) + self.noise * rng.standard_normal(clean.shape))

    def log_likelihood(self, observed, clean):
        mean = np.log(np.clip(clean, 1e-10, 1e4))
        return -0.5 * (((np.log(observed) - mean) / self.noise) ** 2).sum(axis=(1, 2))

    def exact(self, theta):
        from scipy.integrate import solve_ivp

        a, b, c, d = theta
        sol = solve_ivp(lambda t, w: [a - b * np.exp(w[1]), d * np.exp(w[0]) - c],
                        (0, self.times[-1]), [np.log(30.0), 0.0], method="DOP853",
                        rtol=1e-11, atol=1e-11, t_eval=self.times)
        return np.exp(sol.y.T)


TASKS = {"sir": Sir(), "lv": LotkaVolterra()}


def prior(task, rng, m):
    return np.exp(task.mu + task.sigma * rng.standard_normal((m, len(task.mu))))


def log_prior(task, z):
    """Log density of the parameters' logarithms z (up to a constant)."""
    return -0.5 * (((z - task.mu) / task.sigma) ** 2).sum(axis=-1)


def clean_blocks(task, theta, block=20000):
    return np.concatenate([task.clean(theta[i:i + block]) for i in range(0, len(theta), block)])


def simulate(task, theta, rng):
    """Noisy records of `theta`, and which are finite (a diverging
    simulation is dropped, as sbibm drops its solver's failures)."""
    records = task.observe(clean_blocks(task, theta), rng)
    finite = np.isfinite(records).all(axis=(1, 2))
    return records, finite


def save_chart(target, theta, records):
    os.makedirs(target, exist_ok=True)
    np.save(os.path.join(target, "theta.npy"), theta)
    np.save(os.path.join(target, "outputs.npy"), records)


def log_posterior(task, observed, z):
    return task.log_likelihood(observed, clean_blocks(task, np.exp(z))) + log_prior(task, z)


def posterior_mode(task, observed, start, rng):
    """The largest posterior density in the parameters' logarithms, from
    the true parameters and from the best of 20,000 prior draws, and the
    inverse of the Hessian there (finite differences)."""
    from scipy.optimize import minimize

    candidates = np.log(prior(task, rng, 20000))
    scores = log_posterior(task, observed, candidates)
    starts = [np.log(start), candidates[np.argmax(scores)]]
    best = None
    for z0 in starts:
        result = minimize(lambda z: -log_posterior(task, observed, z[None])[0], z0,
                          method="Nelder-Mead",
                          options={"xatol": 1e-9, "fatol": 1e-10, "maxiter": 20000, "maxfev": 40000})
        if best is None or result.fun < best.fun:
            best = result
    mode = best.x
    dim, step = len(mode), 1e-4
    hessian = np.empty((dim, dim))
    points = []
    for j in range(dim):
        for k in range(dim):
            for sj, sk in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                z = mode.copy()
                z[j] += sj * step
                z[k] += sk * step
                points.append(z)
    values = log_posterior(task, observed, np.array(points)).reshape(dim, dim, 4)
    hessian = (values[..., 0] - values[..., 1] - values[..., 2] + values[..., 3]) / (4 * step**2)
    covariance = np.linalg.inv(-hessian)
    covariance = 0.5 * (covariance + covariance.T)
    return mode, covariance


def student_t(rng, mean, covariance, count, dof=5.0):
    """Draws and log densities (up to a constant) of a multivariate t."""
    dim = len(mean)
    chol = np.linalg.cholesky(covariance)
    normal = rng.standard_normal((count, dim))
    scale = np.sqrt(dof / rng.chisquare(dof, count))
    z = mean + (normal * scale[:, None]) @ chol.T
    dev = np.linalg.solve(chol, (z - mean).T)
    log_q = -0.5 * (dof + dim) * np.log1p((dev**2).sum(0) / dof)
    return z, log_q


def reference_draws(task, observed, truth, rng, count=DRAWS):
    """`count` exact posterior draws of one record by rejection sampling,
    with what it took. The proposal starts at the Laplace approximation
    and is moved to the weighted draws' mean and covariance until its
    weights are even enough (a posterior along a curved ridge is not
    its Laplace approximation)."""
    mean, covariance = posterior_mode(task, observed, truth, rng)
    for _ in range(12):
        z, log_q = student_t(rng, mean, 2.25 * covariance, 50_000)
        lw = log_posterior(task, observed, z) - log_q
        w = np.exp(lw - lw.max())
        ess = w.sum() ** 2 / (w**2).sum()
        if ess > 0.2 * len(w):
            break
        p = w / w.sum()
        mean = p @ z
        covariance = ((z - mean).T * p) @ (z - mean)
    batches_z, batches_lw = [], []
    total = 0
    while True:
        z, log_q = student_t(rng, mean, 2.25 * covariance, 100_000)
        lw = log_posterior(task, observed, z) - log_q
        batches_z.append(z)
        batches_lw.append(lw)
        total += len(z)
        lw_all = np.concatenate(batches_lw)
        w = np.exp(lw_all - lw_all.max())
        ess = w.sum() ** 2 / (w**2).sum()
        if w.sum() / 1.2 >= 1.5 * count or total >= 2_000_000:
            break
    z_all = np.concatenate(batches_z)
    accept = rng.uniform(size=len(w)) < w / 1.2
    kept = z_all[accept]
    if len(kept) < count:
        raise SystemExit("only %d of %d draws accepted from %d proposals" % (len(kept), count, total))
    return np.exp(kept[:count]), {"proposals": total, "accepted": int(accept.sum()), "ess": ess}


def write_draws(path, names, draws_per_record):
    with open(path, "w") as out:
        out.write("experiment,draw," + ",".join(names) + "\n")
        for i, draws in enumerate(draws_per_record):
            for k, row in enumerate(draws):
                out.write("%d,%d,%s\n" % (i, k, ",".join(repr(float(v)) for v in row)))


def read_draws(path):
    """Draws by experiment from a CSV of `experiment,draw,<parameters>`."""
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    return [rows[rows[:, 0] == k][:, 2:] for k in np.unique(rows[:, 0])]


def write_records(path, task, records):
    with open(path, "w") as out:
        out.write("experiment," + ",".join(task.outputs) + "\n")
        for i, record in enumerate(records):
            for sample in record:
                out.write("%d,%s\n" % (i, ",".join(repr(float(v)) for v in sample)))


def main():
    command = sys.argv[1] if len(sys.argv) > 1 else ""
    if command == "chart":
        task, target = TASKS[sys.argv[2]], sys.argv[3]
        m = int(sys.argv[4]) if len(sys.argv) > 4 else 100_000
        seed = int(sys.argv[5]) if len(sys.argv) > 5 else 1
        rng = np.random.default_rng(seed)
        theta = prior(task, rng, m)
        records, finite = simulate(task, theta, rng)
        save_chart(target, theta[finite], records[finite])
        print("%d records written, %d dropped (not finite)" % (finite.sum(), (~finite).sum()))
    elif command == "observations":
        task, target = TASKS[sys.argv[2]], sys.argv[3]
        seed = int(sys.argv[4]) if len(sys.argv) > 4 else 1_000_000
        thetas, records = [], []
        for k in range(OBSERVATIONS):
            rng = np.random.default_rng(seed + k)
            while True:
                theta = prior(task, rng, 1)
                record, finite = simulate(task, theta, rng)
                if finite[0]:
                    break
            thetas.append(theta[0])
            records.append(record[0])
        save_chart(target, np.array(thetas), np.array(records))
    elif command == "reference":
        task, folder, out = TASKS[sys.argv[2]], sys.argv[3], sys.argv[4]
        seed = int(sys.argv[5]) if len(sys.argv) > 5 else 12345
        theta = np.load(os.path.join(folder, "theta.npy"))
        records = np.load(os.path.join(folder, "outputs.npy"))
        rng = np.random.default_rng(seed)
        draws = []
        for i, (truth, record) in enumerate(zip(theta, records)):
            d, said = reference_draws(task, record, truth, rng)
            draws.append(d)
            print("observation %d: %d proposals, %d accepted, effective sample size %.0f; "
                  "mean %s, sd %s" % (i, said["proposals"], said["accepted"], said["ess"],
                                      np.array2string(d.mean(0), precision=4),
                                      np.array2string(d.std(0), precision=4)), flush=True)
        write_draws(out, task.names, draws)
    elif command == "grid":
        task, folder, path = TASKS["sir"], sys.argv[2], sys.argv[3]
        records = np.load(os.path.join(folder, "outputs.npy"))
        drawn = read_draws(path)
        for i, record in enumerate(records):
            z = np.log(drawn[i])
            low, high = z.min(0), z.max(0)
            low, high = low - 0.25 * (high - low), high + 0.25 * (high - low)
            axes = [np.linspace(low[j], high[j], 301) for j in range(2)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
            lp = log_posterior(task, record, grid)
            p = np.exp(lp - lp.max())
            p /= p.sum()
            theta = np.exp(grid)
            mean = p @ theta
            sd = np.sqrt(p @ (theta - mean) ** 2)
            ours_mean, ours_sd = drawn[i].mean(0), drawn[i].std(0)
            print("observation %d: grid mean %s sd %s; draws' mean off by %s of their standard "
                  "error, sd by %s" % (i, np.array2string(mean, precision=5),
                                       np.array2string(sd, precision=5),
                                       np.array2string((ours_mean - mean) / (sd / np.sqrt(len(z))),
                                                       precision=2),
                                       np.array2string(ours_sd / sd - 1, precision=3)))
    elif command == "csv":
        folder, out = sys.argv[2], sys.argv[3]
        records = np.load(os.path.join(folder, "outputs.npy"))
        task = TASKS["sir"] if records.shape[2] == 1 else TASKS["lv"]
        write_records(out, task, records)
    elif command == "serve":
        task = TASKS[sys.argv[2]]
        sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                        "protocol"))
        from twostage_protocol import serve

        def batch(thetas, seeds, indices, noiseless=False, input=None):
            clean = clean_blocks(task, np.array(thetas, dtype=float))
            if noiseless:
                return [None] * len(thetas), [c.tolist() for c in clean]
            # Each experiment's noise from its own (seed, index): the same
            # record whatever batch it comes in.
            records = [task.observe(c[None], np.random.default_rng([s, i]))[0]
                       for c, s, i in zip(clean, seeds, indices)]
            return [None] * len(thetas), [r.tolist() for r in records]

        serve(batch=batch)
    elif command == "check":
        task = TASKS[sys.argv[2]]
        rng = np.random.default_rng(7)
        theta = prior(task, rng, 200)
        ours = task.clean(theta)
        worst = 0.0
        for j in range(len(theta)):
            exact = task.exact(theta[j])
            if exact.shape != ours[j].shape:
                continue
            scale = np.maximum(np.abs(exact), 1e-6 if isinstance(task, Sir) else 1e-3)
            worst = max(worst, float(np.max(np.abs(ours[j] - exact) / scale)))
        print("largest relative error of the RK4 records against DOP853 (rtol 1e-11), "
              "200 prior draws: %.2e" % worst)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
