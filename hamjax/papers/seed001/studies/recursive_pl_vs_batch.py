"""Study `recursive-pl-vs-batch`: the gradient (4.1) against batch least squares.

Question: on the same data (Section V.C plant, input (5.1), white output noise at
a given SNR), how do the paper's recursive normalised gradient and the batch
least-squares solution of (3.8) compare in bias, variance and cost? Both use the
same regressor; per realisation the final estimates are kept. Cost is measured
as wall time per realisation of each estimator alone (compiled, vmapped chunk)
and counted in floating-point operations.
"""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ....identification.seed001 import (
    batch_least_squares,
    normalised_gradient_convergence,
    regressor,
)
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.statistics import summarise
from ....montecarlo.timing import time_per_call
from ..plants import paper_case
from ._common import clean_record, headless, periods_option, run_trials, write_summary


NAME = "recursive-pl-vs-batch"
DESCRIPTION = (
    "seed 001: recursive gradient (4.1) vs batch least squares on the same data: "
    "bias, variance, cost"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 50


class CompareTrial(eqx.Module):
    v: jax.Array
    w: jax.Array
    std: jax.Array
    theta_star: jax.Array

    def _data(self, key):
        y = self.w + self.std * jr.normal(key, self.w.shape)
        return regressor(self.v, y, levels=paper_case().levels, order=2), y

    def gradient(self, key):
        phi, y = self._data(key)
        theta, _ = normalised_gradient_convergence(
            phi,
            y,
            theta0=jnp.zeros(10),
            rho=1e6,
            theta_ref=self.theta_star,
            tolerances=jnp.zeros(1),
        )
        return theta

    def batch(self, key):
        phi, y = self._data(key)
        return batch_least_squares(phi, y)

    def __call__(self, key):
        return {"gradient": self.gradient(key), "batch": self.batch(key)}


OPTIONS = (
    periods_option(2000, "periods of (5.1) (14 samples each; default 2000)"),
    StudyOption("snr", 20.0, "output SNR in dB (default 20)", float),
)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    headless()
    import matplotlib.pyplot as plt

    from ....plotting.recursive_pl import theta_labels

    snr = option_values(args, OPTIONS).snr
    out = Path(out)
    case = paper_case()
    periods, v, w = clean_record(case, args, OPTIONS)
    std = float(jnp.sqrt(jnp.mean(w**2))) * 10 ** (-snr / 20)
    theta_star = case.theta_star()
    trial = CompareTrial(v, w, jnp.asarray(std), theta_star)
    budget = dict(realisations=realisations, chunk=chunk, quiet=quiet)
    res = run_trials(
        key, trial, NAME, out / "realisations", args, budget, periods=periods, snr=snr
    )
    stats = {name: summarise(res[name], np.asarray(theta_star)) for name in res}
    keys = jax.vmap(lambda r: jr.fold_in(key, r))(jnp.arange(min(chunk, realisations)))
    seconds = {
        "gradient": time_per_call(trial.gradient, keys),
        "batch": time_per_call(trial.batch, keys),
    }
    n_time, p = int(v.shape[0]), 10
    flops = {"gradient": n_time * (6 * p + 10), "batch": n_time * p * (p + 1) + p**3}
    labels = theta_labels(2)
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(p)
    for off, name in ((-0.2, "gradient"), (0.2, "batch")):
        s = stats[name]
        ax.errorbar(
            x + off,
            np.asarray(s.bias),
            yerr=np.asarray(s.std),
            fmt="o",
            capsize=3,
            label=f"{name}: bias +- std",
        )
    ax.axhline(0, color="grey", lw=0.7)
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("estimate - theta*")
    ax.set_title(
        f"gradient (4.1) vs batch LS, SNR {snr:g} dB, N = {n_time}", fontsize=9
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "bias_std.png", dpi=120)
    rmse = {
        k: float(np.sqrt(np.sum(np.asarray(s.rmse) ** 2))) for k, s in stats.items()
    }
    bias = {k: float(np.linalg.norm(np.asarray(s.bias))) for k, s in stats.items()}
    spread = {
        k: float(np.sqrt(np.sum(np.asarray(s.std) ** 2))) for k, s in stats.items()
    }
    summary = {
        "study": NAME,
        "seed": getattr(args, "seed", None),
        "realisations": realisations,
        "samples": n_time,
        "snr_db": snr,
        "noise_std": std,
        "per_estimator": {k: s.to_dict() for k, s in stats.items()},
        "bias_norm": bias,
        "std_norm": spread,
        "rmse_norm": rmse,
        "seconds_per_realisation": seconds,
        "flops_per_realisation": flops,
        "verdict": (
            f"SNR {snr:g} dB, N = {n_time}: |bias| gradient {bias['gradient']:.3g} vs "
            f"LS {bias['batch']:.3g}; spread (sqrt trace cov) {spread['gradient']:.3g} "
            f"vs {spread['batch']:.3g}; RMSE {rmse['gradient']:.3g} vs "
            f"{rmse['batch']:.3g}. Cost per realisation {seconds['gradient'] * 1e3:.2f} "
            f"ms vs {seconds['batch'] * 1e3:.2f} ms ({flops['gradient']:.2g} vs "
            f"{flops['batch']:.2g} flops); the gradient is O(N p) and recursive, LS "
            "O(N p^2) and needs the whole record."
        ),
    }
    return write_summary(out, summary)
