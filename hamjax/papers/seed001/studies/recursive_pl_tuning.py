"""Study `recursive-pl-tuning`: effect of $\\rho^*$ and of $\\hat\\theta(0)$ on (4.1).

Question (seed 001, Section IV.A): the paper lets $\\hat\\theta(0)$ be arbitrary and
$\\rho^*$ be any upper bound on $\\|\\Theta^*\\|$. How do both change the number of
samples the normalised gradient needs to reach 1e-3 and 1e-6 (max-abs error), and
what happens when $\\rho^* < \\|\\Theta^*\\|$ violates the assumption? Plant and input:
Section V.C, noise-free. Per realisation a random direction $u$; the initial
estimates are $0$ and $\\Theta^* + s \\|\\Theta^*\\| u$ for several $s$; the radii are
multiples of $\\|\\Theta^*\\|$ and $10^6$.
"""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ....identification.seed001 import normalised_gradient_convergence, regressor
from ..plants import paper_case
from ._common import clean_record, headless, periods_option, run_trials, write_summary


NAME = "recursive-pl-tuning"
DESCRIPTION = (
    "seed 001 (4.1): samples to 1e-3/1e-6 against the projection radius rho* and "
    "the initial estimate"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 50
RHO_FACTORS = (0.5, 0.9, 1.01, 2.0, 10.0, None)  # None: rho* = 1e6
START_SCALES = (None, 0.1, 1.0, 10.0, 100.0)  # None: theta(0) = 0
TOLERANCES = (1e-3, 1e-6)


class TuningTrial(eqx.Module):
    phi: jax.Array
    y: jax.Array
    theta_star: jax.Array
    rhos: jax.Array
    scales: jax.Array
    from_zero: jax.Array

    def __call__(self, key):
        u = jr.normal(key, self.theta_star.shape)
        u = u / jnp.linalg.norm(u)
        size = jnp.linalg.norm(self.theta_star)

        def one(rho, scale, zero):
            theta0 = jnp.where(zero, 0.0, 1.0) * (self.theta_star + scale * size * u)
            theta, samples = normalised_gradient_convergence(
                self.phi,
                self.y,
                theta0=theta0,
                rho=rho,
                theta_ref=self.theta_star,
                tolerances=jnp.array(TOLERANCES),
            )
            return samples, jnp.max(jnp.abs(theta - self.theta_star))

        grid = jax.vmap(
            lambda rho: jax.vmap(lambda s, z: one(rho, s, z))(
                self.scales, self.from_zero
            )
        )
        samples, final = grid(self.rhos)
        return {"samples_to_tol": samples, "final_error": final}


OPTIONS = (periods_option(2000, "periods of (5.1) (14 samples each; default 2000)"),)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    headless()
    from ....plotting.recursive_pl import plot_curves

    out = Path(out)
    case = paper_case()
    periods, v, y = clean_record(case, args, OPTIONS)
    phi = regressor(v, y, levels=case.levels, order=2)
    theta_star = case.theta_star()
    size = float(jnp.linalg.norm(theta_star))
    rhos = np.array([1e6 if f is None else f * size for f in RHO_FACTORS])
    scales = np.array([0.0 if s is None else s for s in START_SCALES])
    trial = TuningTrial(
        phi,
        y,
        theta_star,
        jnp.asarray(rhos),
        jnp.asarray(scales),
        jnp.array([s is None for s in START_SCALES]),
    )
    budget = dict(realisations=realisations, chunk=chunk, quiet=quiet)
    res = run_trials(
        key, trial, NAME, out / "realisations", args, budget, periods=periods
    )
    n_time = y.shape[0]
    samples = np.asarray(res["samples_to_tol"], dtype=float)  # (R, rho, start, tol)
    final = np.asarray(res["final_error"])
    rho_names = ["1e6" if f is None else f"{f:g}|theta*|" for f in RHO_FACTORS]
    start_names = ["0" if s is None else f"theta*+{s:g}|theta*|u" for s in START_SCALES]
    table = {}
    for i, rn in enumerate(rho_names):
        for j, sn in enumerate(start_names):
            s = samples[:, i, j]
            conv = s <= n_time
            table[f"rho={rn}, theta0={sn}"] = {
                "fraction_within_1e-3": float(conv[:, 0].mean()),
                "fraction_within_1e-6": float(conv[:, 1].mean()),
                "median_samples_to_1e-3": float(np.median(s[:, 0]))
                if conv[:, 0].all()
                else None,
                "median_samples_to_1e-6": float(np.median(s[:, 1]))
                if conv[:, 1].all()
                else None,
                "median_final_error": float(np.median(final[:, i, j])),
            }
    curves = {}
    for i, rn in enumerate(rho_names):
        med = np.median(
            np.where(samples[:, i, 1:, 1] <= n_time, samples[:, i, 1:, 1], np.nan),
            axis=0,
        )
        curves[f"rho={rn}"] = med
    plot_curves(
        scales[1:],
        curves,
        xlabel="|theta(0) - theta*| / |theta*|",
        ylabel="median samples to 1e-6 (missing: not reached)",
        title=f"(4.1): convergence time vs initial error and rho* (N = {n_time})",
        logx=True,
    ).savefig(out / "samples_vs_start.png", dpi=120)
    key_fast = f"rho=1.01|theta*|, theta0={start_names[-1]}"
    key_slow = f"rho=1e6, theta0={start_names[-1]}"
    key_zero = "rho=1e6, theta0=0"
    summary = {
        "study": NAME,
        "seed": getattr(args, "seed", None),
        "realisations": realisations,
        "theta_star_norm": size,
        "samples": n_time,
        "table": table,
    }
    small = [table[f"rho={f:g}|theta*|, theta0=0"] for f in (0.5, 0.9)]
    fast = table[key_fast]["median_samples_to_1e-6"]
    slow = table[key_slow]["median_samples_to_1e-6"]
    summary["verdict"] = (
        "rho* < |theta*| (0.5, 0.9): fraction within 1e-3 "
        f"{small[0]['fraction_within_1e-3']:.2f}, {small[1]['fraction_within_1e-3']:.2f} "
        f"(median final error {small[0]['median_final_error']:.3g}, "
        f"{small[1]['median_final_error']:.3g}). From theta(0) = 0, rho* = 1e6: median "
        f"samples to 1e-6 {table[key_zero]['median_samples_to_1e-6']}. From 100|theta*| "
        f"away: {slow} with rho* = 1e6 vs {fast} with rho* = 1.01|theta*|"
        + (
            " (a tight radius removes most of the cost of a bad start)."
            if fast is not None and slow is not None and fast < slow
            else "."
        )
    )
    return write_summary(out, summary)
