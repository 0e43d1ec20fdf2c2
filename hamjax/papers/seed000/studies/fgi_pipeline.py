"""Study `fgi-pipeline`: how do NBBI errors in the U_i propagate into G-hat (seed 000)?

The two-stage method of Tables 1-2 on $G = 1/(0.5 s + 1)^2$, straight backlash of
width 0.4, $n = 4$ levels on $[-1, 1]$, at several noise levels $\\sigma$ (the same
$\\sigma$ in both experiments). Per realisation: NBBI (settled average, hold
`--hold`) gives $\\hat U_i$ with standard errors; FGI at $\\omega$ = `--omega` with
$M$ = `--periods` then uses (a) the exact $U_i$ and (b) the NBBI $\\hat U_i$. The
difference is the NBBI error carried into $\\hat G$ through $(a_k, b_k)$:
$\\delta G/G \\approx -\\delta c_k / c_k$. Expected: both errors $\\propto \\sigma$.
"""

from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import float_list, positive_float, positive_int
from ....identification.seed000.fgi_table2 import identify_fgi
from ....models import WhiteNoise, add_noise
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.statistics import loglog_slope
from ....signals import (
    FGIDesign,
    initialisation_step,
    nbbi_staircase,
)
from ....simulation import simulate
from ..border_shapes import cycle_points
from ._common import DT, LEVELS, OMEGA, close_study, settled_nbbi, study_plant


NAME = "fgi-pipeline"
DESCRIPTION = (
    "seed 000 two-stage pipeline: NBBI errors propagated into G-hat; noise-level sweep"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 100


OPTIONS = (
    StudyOption("noises", [0.01, 0.03, 0.1, 0.3, 1.0], "noise stds", float_list),
    DT,
    StudyOption("hold", 20.0, "NBBI hold N*Tr (20)", positive_float),
    OMEGA,
    StudyOption("periods", 50, "FGI M (50)", positive_int),
)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    import matplotlib.pyplot as plt

    opts = option_values(args, OPTIONS)
    noises, dt, hold, omega, M = (
        opts.noises,
        opts.dt,
        opts.hold,
        opts.omega,
        opts.periods,
    )
    levels = np.asarray(LEVELS)
    plant = study_plant()
    G = plant.linear
    U = cycle_points(plant.nonlinearity, levels)
    _, v0 = initialisation_step(levels, duration=hold, dt=dt)
    _, v1 = nbbi_staircase(levels, hold=hold, dt=dt)
    w_nbbi = simulate(plant, jnp.concatenate([v0, v1]), dt=dt)
    design = FGIDesign.settling(levels, omega=omega, dt=dt, periods=M, settle=hold)
    used = design.omega
    _, vf = design.input()
    w_fgi = simulate(plant, jnp.concatenate([v0, vf]), dt=dt)
    kw = dict(**design.identify_kwargs(v0.shape[0]), quadrature="rectangle")
    g1 = complex(np.asarray(G.frequency_response(used)).item())
    n_harm = int(identify_fgi(w_fgi, U, **kw).harmonics.shape[0])

    def trial(key_r):
        out = {"exact": [], "nbbi": [], "u_err": [], "kept": []}
        for i, sigma in enumerate(noises):
            nbbi_key, fgi_key = jr.split(jr.fold_in(key_r, i))
            y1 = add_noise(nbbi_key, w_nbbi, WhiteNoise(sigma))
            y2 = add_noise(fgi_key, w_fgi, WhiteNoise(sigma))
            est = settled_nbbi(y1, levels, hold=hold, dt=dt, start=v0.shape[0])
            exact = identify_fgi(y2, U, throw=False, **kw)
            piped = identify_fgi(
                y2, est.cycle_values, cycle_stderr=est.uncertainty, throw=False, **kw
            )
            out["exact"].append(jnp.abs(exact.g[0] - g1))
            out["nbbi"].append(jnp.abs(piped.g[0] - g1))
            out["u_err"].append(jnp.sqrt(jnp.mean((est.cycle_values - U) ** 2)))
            out["kept"].append(piped.keep)
        return {k: jnp.stack(v) for k, v in out.items()}

    mc_key, boot_key = jr.split(key)
    res = run_monte_carlo(
        mc_key,
        trial,
        MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
        quiet=quiet,
    )
    s = np.asarray(noises)
    summary = {
        "study": NAME,
        "question": "How do NBBI errors in U_i propagate into G-hat(j w)? (k = 1)",
        "realisations": realisations,
        "noises": noises,
        "omega": used,
        "periods": M,
        "hold": hold,
        "dt": dt,
    }
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    verdict = []
    for j, name in enumerate(("exact", "nbbi", "u_err")):
        e = np.asarray(res[name])
        rmse = np.sqrt(np.mean(e**2, axis=0))
        fit = loglog_slope(s, e, key=jr.fold_in(boot_key, j)).to_dict()
        summary[name] = {"rmse": rmse.tolist(), "fit": fit}
        verdict.append(
            f"{name}: slope in sigma {fit['slope']:.3f} CI "
            f"[{fit['ci'][0]:.3f}, {fit['ci'][1]:.3f}]"
        )
        label = {
            "exact": "|G-hat - G|, exact U",
            "nbbi": "|G-hat - G|, NBBI U-hat",
            "u_err": "RMS(U-hat - U)",
        }[name]
        ax.loglog(s, rmse, "o-", label=label)
    ratio = np.asarray(summary["nbbi"]["rmse"]) / np.asarray(summary["exact"]["rmse"])
    summary["ratio_nbbi_over_exact"] = ratio.tolist()
    kept = np.asarray(res["kept"]).mean(axis=0)  # (noise, harmonic)
    summary["keep_frequency"] = {
        f"sigma={sg:g}": {
            int(k + 1): float(kept[i, k]) for k in range(n_harm) if kept[i, k] > 0
        }
        for i, sg in enumerate(noises)
    }
    verdict.append(
        "error ratio (NBBI U / exact U): " + ", ".join(f"{r:.2f}" for r in ratio)
    )
    ax.set_xlabel("noise std sigma")
    ax.set_ylabel("RMS error")
    ax.set_title(f"NBBI -> FGI pipeline (R = {realisations}, k = 1, w = {used:.3g})")
    return close_study(fig, ax, out, "fgi_pipeline", summary, verdict)
