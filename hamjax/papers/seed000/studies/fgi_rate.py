"""Study `fgi-rate`: Proposition 2 of seed 000 - how fast does G-hat_M converge in M?

Plant $G = 1/(0.5 s + 1)^2$, straight backlash of width 0.4, $n = 4$ levels on
$[-1, 1]$, exact $U_i$ (the NBBI stage is taken as perfect, as in Section IV),
$\\omega$ = `--omega`, white output noise of std `--noise` at `--dt`. One record of
$M_{max}$ periods per realisation (after the transient); $\\hat G_M(jk\\omega)$ for
each $M$ from its first $M$ periods. The (22) integrals use the periodic rectangle
rule so that the discretisation floor (reported for both quadratures) is far below
the noise. Expected: $|\\hat G_M - G| \\propto M^{-1/2}$ for every kept harmonic.
"""

from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import int_list
from ....identification.seed000.fgi_table2 import identify_fgi
from ....models import WhiteNoise, add_noise
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.statistics import loglog_slope
from ....signals import FGIDesign, initialisation_step
from ....simulation import simulate
from ..border_shapes import cycle_points
from ._common import DT, LEVELS, OMEGA, close_study, noise_option, study_plant


NAME = "fgi-rate"
DESCRIPTION = (
    "seed 000 Prop. 2: |G-hat_M(jk w) - G(jk w)| vs M per harmonic; log-log slopes "
    "with CI"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 50


OPTIONS = (
    noise_option(0.3),
    DT,
    OMEGA,
    StudyOption(
        "ms",
        [1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1000],
        "comma-separated M values",
        int_list,
    ),
)


def setup(*, omega: float, dt: float, m_max: int):
    levels = np.asarray(LEVELS)
    plant = study_plant()
    G = plant.linear
    U = cycle_points(plant.nonlinearity, levels)
    # 10 s of transient >> the settling time of G
    design = FGIDesign.settling(levels, omega=omega, dt=dt, periods=m_max, settle=10.0)
    _, v0 = initialisation_step(levels, duration=5.0, dt=dt)
    _, v1 = design.input()
    w = simulate(plant, jnp.concatenate([v0, v1]), dt=dt)
    return G, U, design.period_samples, design.omega, design.start(v0.shape[0]), w


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    import matplotlib.pyplot as plt

    opts = option_values(args, OPTIONS)
    noise, dt, omega, ms = opts.noise, opts.dt, opts.omega, opts.ms
    G, U, P, used, start, w = setup(omega=omega, dt=dt, m_max=max(ms))
    kw = dict(period_samples=P, dt=dt, start=start)
    ref = identify_fgi(w, U, periods=1, quadrature="rectangle", **kw)
    keep = np.asarray(ref.keep)
    ks = np.asarray(ref.harmonics)[keep]
    truth = np.asarray(G.frequency_response(ks * used))
    floor_hold = identify_fgi(w, U, periods=1, quadrature="hold", **kw)
    floors = {
        "rectangle": np.abs(np.asarray(ref.g)[keep] - truth).tolist(),
        "hold": np.abs(np.asarray(floor_hold.g)[keep] - truth).tolist(),
    }
    idx = jnp.asarray(np.flatnonzero(keep))

    def trial(key_r):
        y = add_noise(key_r, w, WhiteNoise(noise))
        errs = []
        for M in ms:
            res = identify_fgi(
                y, U, periods=M, quadrature="rectangle", throw=False, **kw
            )
            errs.append(jnp.abs(res.g[idx] - truth))
        return jnp.stack(errs, axis=-1)  # (harmonic, M)

    mc_key, boot_key = jr.split(key)
    e = np.asarray(
        run_monte_carlo(
            mc_key,
            trial,
            MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
            quiet=quiet,
        )
    )
    ms_a = np.asarray(ms, dtype=float)
    summary = {
        "study": NAME,
        "question": "Prop. 2: G-hat_M(jk w) -> G(jk w) as M grows; at which rate?",
        "realisations": realisations,
        "noise_std": noise,
        "dt": dt,
        "omega": used,
        "period_samples": P,
        "ms": ms,
        "harmonics": ks.tolist(),
        "discretisation_floor": floors,
        "per_harmonic": [],
    }
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    verdict = []
    for j, k in enumerate(ks):
        ej = e[:, j, :]
        rmse = np.sqrt(np.mean(ej**2, axis=0))
        fit = loglog_slope(ms_a, ej, key=jr.fold_in(boot_key, j)).to_dict()
        ok = fit["ci"][0] <= -0.5 <= fit["ci"][1]
        verdict.append(
            f"k={k}: slope {fit['slope']:.3f} CI [{fit['ci'][0]:.3f}, {fit['ci'][1]:.3f}]"
            f" {'consistent with' if ok else 'NOT'} -1/2"
        )
        summary["per_harmonic"].append({"k": int(k), "rmse": rmse.tolist(), "fit": fit})
        ax.loglog(ms_a, rmse, "o-", label=f"k = {k} (slope {fit['slope']:.2f})")
    ax.loglog(
        ms_a,
        np.sqrt(np.mean(e[:, 0, :] ** 2, axis=0))[0] / np.sqrt(ms_a),
        "k--",
        lw=1,
        label=r"$\propto M^{-1/2}$",
    )
    ax.set_xlabel("M (periods averaged)")
    ax.set_ylabel(r"RMS $|\hat G_M(jk\omega) - G(jk\omega)|$")
    ax.set_title(f"FGI, Prop. 2 (R = {realisations}, omega = {used:.3g})")
    return close_study(fig, ax, out, "fgi_rate", summary, verdict)
