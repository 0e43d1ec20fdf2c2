"""Seed 000's example reproduced: NBBI (Table 1) and FGI (Table 2) on the Fig. 6
plant $G(s) = (s-10)/(s+1)^2$ with a curved backlash (Figs. 5, 6 and a Bode plot).

Used by `hamjax reproduce backlash-frequency` and by the demo.
"""

from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ... import models as hm, signals, simulation
from ...identification.seed000.fgi_table2 import identify_fgi
from ...identification.seed000.nbbi_table1 import check_assumptions, identify_nbbi
from ...io import write_json
from .border_shapes import cycle_points
from .plants import seed000_plant


def demo_run(key, out: Path) -> list[tuple[str, str]]:
    """Demo section (`hamjax demo`): the defaults of `reproduce`."""
    return run_example(
        key, out, noise=0.5, hold=40.0, omegas=[0.05, 0.2, 0.6, 2.0], periods=20
    )[1]


def _borders(nonlinearity):
    """(f_a, f_d) of the normalised backlash, in output units, for the figure."""
    gain, inner = 1.0, nonlinearity
    if hasattr(inner, "gain") and hasattr(inner, "inner"):
        gain, inner = inner.gain, inner.inner
    return (
        lambda v: gain * inner.ascending(jnp.asarray(v)),
        lambda v: gain * inner.descending(jnp.asarray(v)),
    )


def run_example(key, out: Path, *, noise, hold, omegas, periods):
    """Simulate Table 1 and Table 2 on the Fig. 6 plant; write figures and JSON."""
    import matplotlib.pyplot as plt

    from ...plotting.backlash import plot_bode, plot_cycle, plot_nbbi_experiment

    nbbi_key, fgi_key = jr.split(key)
    plant, levels, dt, _ = seed000_plant()  # normalised: G(0) = 1 by (kF, G/k)
    check_assumptions(plant.linear)
    levels = np.asarray(levels)
    raw_G = hm.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0])

    # Table 1: initialisation (3) + staircase (4a-b), noisy output (Fig. 6).
    _, v0 = signals.initialisation_step(levels, duration=hold, dt=dt)
    _, v1 = signals.nbbi_staircase(levels, hold=hold, dt=dt)
    v = jnp.concatenate([v0, v1])
    t = jnp.arange(v.shape[0]) * dt
    w = simulation.simulate(plant, v, dt=dt)
    y = hm.add_noise(nbbi_key, w, hm.WhiteNoise(noise))
    start = v0.shape[0]
    plain = identify_nbbi(y, levels, hold=hold, dt=dt, start=start)
    settled = identify_nbbi(y, levels, hold=hold, dt=dt, start=start, discard=hold / 2)
    truth = np.asarray(cycle_points(plant.nonlinearity, levels))

    made = []
    fig = plot_nbbi_experiment(t, v, y, w=w)
    fig.savefig(out / "fig6_nbbi_experiment.png", dpi=110)
    made.append(("fig6_nbbi_experiment.png", "input (3)+(4a-b), noisy output (Fig. 6)"))
    fig = plot_cycle(
        settled,
        borders=_borders(plant.nonlinearity),
        true_values=truth,
        title="Backlash cycle points from NBBI, settled average (gain k = G(0) = -10)",
    )
    fig.savefig(out / "fig5_cycle_points.png", dpi=110)
    made.append(("fig5_cycle_points.png", "limit cycle with NBBI points (Fig. 5)"))
    plt.close("all")

    # Table 2 at each omega (Remark 2a), u reconstructed from the NBBI points.
    results, entries = [], []
    for i, omega in enumerate(omegas):
        design = signals.FGIDesign.settling(
            levels, omega=omega, dt=dt, periods=periods, settle=hold
        )
        _, vf = design.input()
        vf = jnp.concatenate([v0, vf])
        wf = simulation.simulate(plant, vf, dt=dt)
        yf = hm.add_noise(jr.fold_in(fgi_key, i), wf, hm.WhiteNoise(noise))
        res = identify_fgi(
            yf,
            settled.cycle_values,
            **design.identify_kwargs(v0.shape[0]),
            cycle_stderr=settled.uncertainty,
        )
        results.append(res)
        for e in res.frequency_response():
            g = complex(np.asarray(raw_G.frequency_response(e["omega"])).item()) / -10.0
            e["true_re"], e["true_im"] = g.real, g.imag
            e["abs_error"] = abs(complex(e["re"], e["im"]) - g)
            entries.append(e)
    fig = plot_bode(results, linear=plant.linear)
    fig.savefig(out / "bode_fgi.png", dpi=110)
    made.append(("bode_fgi.png", "Bode plot of G-hat (FGI) against G"))
    plt.close("all")

    summary = {
        "plant": "G(s) = (s-10)/(s+1)^2 normalised by k = G(0) = -10; n = 4",
        "levels": levels.tolist(),
        "dt": dt,
        "hold": hold,
        "noise_std": noise,
        "nbbi": {
            "true_cycle": truth.tolist(),
            "plain": np.asarray(plain.cycle_values).tolist(),
            "settled": np.asarray(settled.cycle_values).tolist(),
            "stderr": np.asarray(settled.stderr).tolist(),
            "max_abs_error_plain": float(np.max(np.abs(plain.cycle_values - truth))),
            "max_abs_error_settled": float(
                np.max(np.abs(settled.cycle_values - truth))
            ),
        },
        "fgi": {
            "periods": periods,
            "frequency_response": entries,
            "n_points": len(entries),
            "max_abs_error": max(
                (e["abs_error"] for e in entries), default=float("nan")
            ),
        },
    }
    write_json(out / "backlash_frequency.json", summary)
    made.append(("backlash_frequency.json", "estimates, truth and errors"))
    return summary, made
