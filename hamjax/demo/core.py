"""Demo section: the built-in plants, their inputs and outputs (issue "hamjax core")."""

from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .. import models as hm, signals, simulation
from ..papers.seed000.plants import seed000_border_shapes, seed000_plant
from ..papers.seed001.plants import seed001_plant
from ..plotting.responses import plot_characteristic, plot_input_output


def run(key, out: Path) -> list[tuple[str, str]]:
    made = []
    noise000_key, noise001_key = jr.split(key)

    # Seed 000, Fig. 6: normalised plant, initialisation (3) + staircase (4a-b).
    plant, levels, dt, hold = seed000_plant()
    _, v0 = signals.initialisation_step(levels, duration=hold / 4, dt=dt)
    _, v1 = signals.nbbi_staircase(levels, hold=hold, dt=dt)
    v = jnp.concatenate([v0, v1])
    t = jnp.arange(v.shape[0]) * dt
    made.append(
        _input_output(
            out / "seed000_staircase_io.png",
            "input (3)+(4a-b) and noisy output of the "
            "normalised Fig. 6 plant (analogue of seed 000 Fig. 6)",
            noise000_key,
            plant,
            (t, v),
            noise_std=0.5,
            dt=dt,
            title="Backlash plant (s-10)/(s+1)^2: staircase experiment of NBBI, "
            "4 levels",
        )
    )

    # The physical backlash (before the (kF, G/k) normalisation, k = G(0) = -10).
    bl = seed000_border_shapes()
    lo, hi = float(levels[0]), float(levels[-1])
    # Initialisation (3) as a sweep down from v_M, then one full cycle.
    sweep = jnp.concatenate(
        [
            jnp.linspace(hi, lo, 300),
            jnp.linspace(lo, hi, 300),
            jnp.linspace(hi, lo, 300),
        ]
    )
    u_sweep = hm.apply_nonlinearity(bl, sweep)[300:]
    u_stair = hm.apply_nonlinearity(bl, v)
    grid = jnp.linspace(lo - 0.3, hi + 0.3, 300)
    fig = plot_characteristic(
        sweep[300:],
        u_sweep,
        borders=(bl.ascending, bl.descending),
        grid=grid,
        title="backlash cycle (before normalisation)",
    )
    fig.axes[0].plot(
        np.asarray(v[v0.shape[0] :]),
        np.asarray(u_stair[v0.shape[0] :]),
        "o",
        ms=7,
        mfc="none",
        color="C1",
        label="positions visited by (4a-b)",
    )
    fig.axes[0].legend(fontsize=8)
    fig.savefig(out / "seed000_backlash_cycle.png", dpi=110)
    made.append(
        (
            "seed000_backlash_cycle.png",
            "the backlash cycle traced by a slow "
            "sweep, with the positions the staircase visits (cf. seed 000 Fig. 5)",
        )
    )

    # Seed 001, Section V.C: PE impulse input (5.1).
    plant1, levels1, order = seed001_plant()
    made.append(
        _input_output(
            out / "seed001_pe_io.png",
            "the persistently exciting input (5.1) and the "
            "output of the Section V.C plant",
            noise001_key,
            plant1,
            signals.pe_impulse_sequence(levels1, order=order, periods=6),
            noise_std=0.1,
            dt=None,
            title="Piecewise-linear plant: persistently exciting impulse input, "
            "6 periods",
        )
    )
    return made


def _input_output(
    path: Path, caption: str, key, plant, tv, *, noise_std: float, dt, title: str
) -> tuple[str, str]:
    """Simulate `plant` on the input `tv = (t, v)`, add white noise of `noise_std`
    drawn with `key`, and save the input/output figure at `path`: `(name, caption)`."""
    t, v = tv
    w = simulation.simulate(plant, v, dt=dt)
    y = hm.add_noise(key, w, hm.WhiteNoise(noise_std))
    fig = plot_input_output(t, v, y, w=w, title=title)
    fig.savefig(path, dpi=110)
    return path.name, caption
