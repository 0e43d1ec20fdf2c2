"""Study `nbbi-shapes`: does NBBI recover the cycle for every border shape (seed 000,
Remark 1b)?

Shapes of `hamjax.papers.seed000.border_shapes`: straight, non-smooth, non-invertible,
discontinuous (relay-like), crossing, superposed (a static map: "he who can do
more must be able to do less") and the Fig. 4b composition. Plant
$G = 1/(0.5 s + 1)^2$, $n$ = `--levels` on $[-1, 1]$, settled average, hold
`--hold`, white noise `--noise`. Per shape: noise-free error (must be ~0), the
noisy RMSE over the $2n-2$ points, and which points lie on a border ($U_i =
f_a(V_i)$ on $\\mathcal P_a$, $f_d(V_i)$ on $\\mathcal P_d$) rather than on a
horizontal segment of the cycle (where NBBI cannot see the border: the working
point has not reached it), plus FGI's $|\\hat G(j\\omega) - G(j\\omega)|$ with $\\hat U$.
"""

import math
from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import positive_float, positive_int
from ...._results import RESULTS
from ....identification.seed000.fgi_table2 import identify_fgi
from ....io import write_json
from ....models import Hammerstein, WhiteNoise, add_noise
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....signals import (
    FGIDesign,
    initialisation_step,
    nbbi_staircase,
)
from ....signals.staircase import staircase_cycle_levels
from ....simulation import simulate
from ..border_shapes import SHAPES, cycle_points
from ._common import DT, noise_option, settled_nbbi, study_linear


NAME = "nbbi-shapes"
DESCRIPTION = (
    "seed 000 Remark 1b: NBBI (+FGI) on straight, non-smooth, non-invertible, relay, "
    "crossing, superposed (static) and composed borders"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 100


OPTIONS = (
    noise_option(0.05),
    StudyOption("levels", 9, "n levels on [-1, 1] (9)", positive_int),
    StudyOption("hold", 20.0, "hold N*Tr (20)", positive_float),
    DT,
)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    import matplotlib.pyplot as plt

    from ....plotting.backlash import plot_cycle

    opts = option_values(args, OPTIONS)
    noise, n, hold, dt = opts.noise, opts.levels, opts.hold, opts.dt
    levels = np.linspace(-1.0, 1.0, n)
    cyc = np.asarray(staircase_cycle_levels(levels))
    G = study_linear()
    _, v0 = initialisation_step(levels, duration=hold, dt=dt)
    _, v1 = nbbi_staircase(levels, hold=hold, dt=dt)
    v_nbbi = jnp.concatenate([v0, v1])
    design = FGIDesign.settling(levels, omega=1.0, dt=dt, periods=20, settle=hold)
    used = design.omega
    _, vf = design.input()
    v_fgi = jnp.concatenate([v0, vf])
    fkw = dict(**design.identify_kwargs(v0.shape[0]), quadrature="rectangle")
    g_true = np.asarray(G.frequency_response(jnp.arange(1, 65) * used))
    names = sorted(SHAPES)
    setups, summary_shapes = [], {}
    for name in names:
        bl = SHAPES[name]()
        plant = Hammerstein(bl, G)
        U = cycle_points(bl, levels)
        w1 = simulate(plant, v_nbbi, dt=dt)
        w2 = simulate(plant, v_fgi, dt=dt)
        clean = settled_nbbi(w1, levels, hold=hold, dt=dt, start=v0.shape[0])
        fa, fd = np.asarray(bl.ascending(cyc)), np.asarray(bl.descending(cyc))
        Un = np.asarray(U)
        on_border = np.r_[np.isclose(Un[:n], fa[:n]), np.isclose(Un[n:], fd[n:])]
        on_border[0] = np.isclose(Un[0], fd[0])  # point 1 = (v_m, f_d(v_m))
        ref = identify_fgi(w2, U, throw=False, **fkw)
        summary_shapes[name] = {
            "true_cycle": Un.tolist(),
            "noise_free_max_error": float(
                np.max(np.abs(np.asarray(clean.cycle_values) - Un))
            ),
            "noise_free_result": bool(clean.result == RESULTS.successful),
            "points_on_a_border": int(on_border.sum()),
            "points_on_horizontal_segments": int((~on_border).sum()),
            "fgi_kept_harmonics": np.asarray(ref.harmonics)[
                np.asarray(ref.keep)
            ].tolist(),
        }
        setups.append((w1, w2, U, clean))

    def trial(key_r):
        res = {"nbbi_rmse": [], "g1_err": []}
        for i, (w1, w2, U, _) in enumerate(setups):
            k1, k2 = jr.split(jr.fold_in(key_r, i))
            y1 = add_noise(k1, w1, WhiteNoise(noise))
            est = settled_nbbi(y1, levels, hold=hold, dt=dt, start=v0.shape[0])
            fgi = identify_fgi(
                add_noise(k2, w2, WhiteNoise(noise)),
                est.cycle_values,
                cycle_stderr=est.uncertainty,
                throw=False,
                **fkw,
            )
            res["nbbi_rmse"].append(jnp.sqrt(jnp.mean((est.cycle_values - U) ** 2)))
            res["g1_err"].append(
                jnp.where(fgi.keep[0], jnp.abs(fgi.g[0] - g_true[0]), jnp.nan)
            )
        return {k: jnp.stack(v) for k, v in res.items()}

    res = run_monte_carlo(
        key,
        trial,
        MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
        quiet=quiet,
    )
    se_theory = noise * math.sqrt(dt / (hold / 2))
    verdict = []
    for i, name in enumerate(names):
        e = np.asarray(res["nbbi_rmse"])[:, i]
        g = np.asarray(res["g1_err"])[:, i]
        d = summary_shapes[name]
        d["nbbi_rmse"] = float(np.sqrt(np.mean(e**2)))
        d["nbbi_rmse_over_white_noise_se"] = d["nbbi_rmse"] / se_theory
        d["fgi_k1_rmse"] = (
            float(np.sqrt(np.nanmean(g**2))) if np.any(np.isfinite(g)) else None
        )
        d["fgi_k1_kept_fraction"] = float(np.mean(np.isfinite(g)))
        verdict.append(
            f"{name}: noise-free err {d['noise_free_max_error']:.1e}, RMSE/se "
            f"{d['nbbi_rmse_over_white_noise_se']:.2f}, {d['points_on_a_border']}/"
            f"{2 * n - 2} on a border, |G1| err {d['fgi_k1_rmse']}"
        )
    fig, axes = plt.subplots(2, math.ceil(len(names) / 2), figsize=(14, 6.5))
    for ax, name, (_, _, U, clean) in zip(axes.ravel(), names, setups, strict=False):
        bl = SHAPES[name]()
        plot_cycle(
            clean,
            borders=(bl.ascending, bl.descending),
            true_values=U,
            title=name,
            ax=ax,
        )
        ax.legend().remove()
    for ax in axes.ravel()[len(names) :]:
        ax.remove()
    fig.tight_layout()
    fig.savefig(Path(out) / "nbbi_shapes.png", dpi=100)
    plt.close(fig)
    summary = {
        "study": NAME,
        "question": "Remark 1b: NBBI for arbitrary borders incl. static maps",
        "realisations": realisations,
        "noise_std": noise,
        "levels": levels.tolist(),
        "hold": hold,
        "dt": dt,
        "white_noise_se_settled": se_theory,
        "shapes": summary_shapes,
        "verdict": verdict,
        "headline": "; ".join(verdict),
    }
    write_json(Path(out) / "nbbi_shapes.json", summary)
    return summary
