"""sbi's NPE on the same simulations as twostage's network: the field's
reference method beside twostage's draws in docs/accuracy.md (issue 71).

    python3 npe.py TASK CHART OBS OUT.csv [SEED]

CHART and OBS are folders of `tasks.py chart` / `tasks.py observations`
(theta.npy, outputs.npy). NPE (sbi's default: a masked autoregressive
flow, inputs and parameters z-scored, its own held-out stopping) is
trained on the chart, and 10,000 draws of each observation are written
as `tasks.py reference` writes its draws, for `cargo xtask c2st`.

Both tasks' priors are log-normal: NPE is trained on the parameters'
logarithms, whose prior is a normal, and its draws are mapped back; the
flow then never proposes outside the support and needs no rejection.
Needs `pip install sbi` (with torch).
"""

import sys

import numpy as np
import torch

import tasks


def main():
    task = tasks.TASKS[sys.argv[1]]
    chart, obs, out = sys.argv[2], sys.argv[3], sys.argv[4]
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    from sbi.inference import NPE

    torch.manual_seed(seed)
    theta = np.load(chart + "/theta.npy")
    records = np.load(chart + "/outputs.npy").reshape(len(theta), -1)
    prior = torch.distributions.MultivariateNormal(
        torch.tensor(task.mu, dtype=torch.float32),
        torch.diag(torch.tensor(task.sigma, dtype=torch.float32) ** 2),
    )
    inference = NPE(prior=prior)
    inference.append_simulations(
        torch.tensor(np.log(theta), dtype=torch.float32),
        torch.tensor(records, dtype=torch.float32),
    )
    network = inference.train()
    posterior = inference.build_posterior(network)
    observed = np.load(obs + "/outputs.npy")
    draws = []
    for record in observed:
        x = torch.tensor(record.reshape(1, -1), dtype=torch.float32)
        z = posterior.sample((tasks.DRAWS,), x=x, show_progress_bars=False)
        draws.append(np.exp(z.numpy().astype(float)))
    tasks.write_draws(out, task.names, draws)
    print("%d simulations, %d epochs" % (len(theta), inference.epoch))


if __name__ == "__main__":
    main()
