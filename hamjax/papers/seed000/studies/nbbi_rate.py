"""Study `nbbi-rate`: Proposition 1 of seed 000 - how fast do NBBI points converge in N?

Plant $G = 1/(0.5 s + 1)^2$ ($G(0) = 1$, sum of time constants 1 s, $T_r = 1$ s),
straight backlash of width 0.4, $n = 4$ levels on $[-1, 1]$, white output noise of
std `--noise` sampled at `--dt`. For each $N$ the staircase (4a-b) holds each level
$N T_r$ seconds; the error of a realisation is the RMS over the $2n-2$ points of
$\\hat W_i(N) - U_i$. Plain average (5) against the settled average (second half).
Expected: plain RMSE $\\approx \\sqrt{b^2/N^2 + s^2/N}$ (1/N transient bias, then
$N^{-1/2}$ noise, crossover $N^* = b^2/s^2$); settled $\\propto N^{-1/2}$.
"""

import math
from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import int_list
from ....identification.seed000.nbbi_table1 import identify_nbbi
from ....models import WhiteNoise, add_noise
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.statistics import loglog_slope
from ....signals import initialisation_step, nbbi_staircase
from ....simulation import simulate
from ..border_shapes import cycle_points
from ._common import DT, LEVELS, close_study, noise_option, study_plant


NAME = "nbbi-rate"
DESCRIPTION = (
    "seed 000 Prop. 1: NBBI border-point RMSE vs N, plain (5) vs settled average; "
    "log-log slopes with CI"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 50
T_R = 1.0


OPTIONS = (
    noise_option(0.3),
    DT,
    StudyOption(
        "ns",
        [3, 6, 12, 25, 50, 100, 200, 400, 1000],
        "comma-separated N values (hold = N * Tr, Tr = 1 s)",
        int_list,
    ),
)


def make_trial(ns, *, noise: float, dt: float):
    """`trial(key) -> {"plain": (n_N, 2n-2), "settled": ...}` signed point errors."""
    levels = np.asarray(LEVELS)
    plant = study_plant()
    truth = cycle_points(plant.nonlinearity, levels)
    records = []
    for N in ns:
        hold = N * T_R
        _, v0 = initialisation_step(levels, duration=hold, dt=dt)
        _, v1 = nbbi_staircase(levels, hold=hold, dt=dt)
        w = simulate(plant, jnp.concatenate([v0, v1]), dt=dt)
        records.append((hold, v0.shape[0], w))

    def trial(key):
        plain, settled = [], []
        for i, (hold, start, w) in enumerate(records):
            y = add_noise(jr.fold_in(key, i), w, WhiteNoise(noise))
            half = math.floor(round(hold / dt) / 2) * dt
            for out, discard in ((plain, 0.0), (settled, half)):
                res = identify_nbbi(
                    y,
                    levels,
                    hold=hold,
                    dt=dt,
                    start=start,
                    discard=discard,
                    throw=False,
                )
                out.append(res.cycle_values - truth)
        return {"plain": jnp.stack(plain), "settled": jnp.stack(settled)}

    return trial


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    import matplotlib.pyplot as plt

    opts = option_values(args, OPTIONS)
    noise, dt, ns = opts.noise, opts.dt, opts.ns
    mc_key, boot_key = jr.split(key)
    trial = make_trial(ns, noise=noise, dt=dt)
    res = run_monte_carlo(
        mc_key,
        trial,
        MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
        quiet=quiet,
    )
    ns_a = np.asarray(ns, dtype=float)
    # Theory: bias b/N with b = RMS of jumps * (sum of time constants = 1 s);
    # noise s^2/N with s^2 = sigma^2 dt / Tr.
    levels = np.asarray(LEVELS)
    truth = np.asarray(cycle_points(study_plant().nonlinearity, levels))
    jumps = np.diff(np.r_[truth[0], truth])
    b = float(np.sqrt(np.mean(jumps**2)) * 1.0 / T_R)
    s2 = noise**2 * dt / T_R
    n_star = b**2 / s2
    summary = {
        "study": NAME,
        "question": "Prop. 1: NBBI points converge as N grows; at which rate?",
        "realisations": realisations,
        "noise_std": noise,
        "dt": dt,
        "ns": ns,
        "predicted_crossover_N": n_star,
    }
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for j, name in enumerate(("plain", "settled")):
        signed = np.asarray(res[name])  # (R, n_N, 2n-2)
        e = np.sqrt(np.mean(signed**2, axis=-1))  # per-realisation RMS over points
        rmse = np.sqrt(np.mean(e**2, axis=0))
        bias = np.sqrt(np.mean(np.mean(signed, axis=0) ** 2, axis=-1))
        spread = np.sqrt(np.mean(np.var(signed, axis=0, ddof=1), axis=-1))
        mcse = np.std(e**2, axis=0, ddof=1) / np.sqrt(e.shape[0]) / (2 * rmse)
        fits = {}
        regions = {
            "all": ns_a > 0,
            "bias_region": ns_a <= n_star / 4,
            "noise_region": ns_a >= 4 * n_star if name == "plain" else ns_a >= 25,
        }
        for region, mask in regions.items():
            if mask.sum() >= 2:
                fit = loglog_slope(
                    ns_a[mask], e[:, mask], key=jr.fold_in(boot_key, 10 * j + len(fits))
                )
                fits[region] = {"ns": ns_a[mask].tolist(), **fit.to_dict()}
        big = bias > 5 * spread / np.sqrt(e.shape[0])  # bias resolved above MC noise
        if big.sum() >= 3:
            fit = loglog_slope(ns_a[big], bias[big])
            fits["bias_component"] = {"ns": ns_a[big].tolist(), **fit.to_dict()}
        fit = loglog_slope(ns_a, spread)
        fits["noise_component"] = {"ns": ns_a.tolist(), **fit.to_dict()}
        summary[name] = {
            "rmse": rmse.tolist(),
            "rmse_mcse": mcse.tolist(),
            "bias_rms_over_points": bias.tolist(),
            "std_rms_over_points": spread.tolist(),
            "fits": fits,
        }
        ax.errorbar(
            ns_a, rmse, yerr=1.96 * mcse, marker="o", capsize=2, label=f"{name} average"
        )
    theory_plain = np.sqrt(b**2 / ns_a**2 + s2 / ns_a)
    ax.loglog(ns_a, theory_plain, "k--", lw=1, label=r"$\sqrt{b^2/N^2 + s^2/N}$")
    ax.loglog(ns_a, np.sqrt(2 * s2 / ns_a), "k:", lw=1, label=r"$\sqrt{2 s^2/N}$")
    ax.axvline(n_star, color="0.6", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("N (hold = N Tr)")
    ax.set_ylabel("RMS error of the 2n-2 points")
    ax.set_title(f"NBBI, Prop. 1 (R = {realisations}); crossover N* = {n_star:.0f}")
    p, s = summary["plain"]["fits"], summary["settled"]["fits"]
    verdict = []
    for label, fit, want in (
        ("plain, bias component", p.get("bias_component"), -1.0),
        ("plain, noise component", p.get("noise_component"), -0.5),
        ("plain RMSE, bias region", p.get("bias_region"), -1.0),
        ("plain, noise region", p.get("noise_region"), -0.5),
        ("settled, N >= 25", s.get("noise_region"), -0.5),
    ):
        if fit:
            ok = fit["ci"][0] <= want <= fit["ci"][1]
            verdict.append(
                f"{label}: slope {fit['slope']:.3f} CI [{fit['ci'][0]:.3f}, "
                f"{fit['ci'][1]:.3f}] vs {want} -> {'consistent' if ok else 'NOT in CI'}"
            )
    return close_study(fig, ax, out, "nbbi_rate", summary, verdict)
