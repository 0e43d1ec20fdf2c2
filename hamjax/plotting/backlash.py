"""Seed 000 figures: the limit cycle with NBBI points (Fig. 5), the NBBI
experiment (Fig. 6) and the Bode plot of the FGI estimates."""

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..identification.seed000.fgi_table2 import FGIResult
from ..identification.seed000.nbbi_table1 import NBBIResult


def plot_cycle(
    result: NBBIResult,
    *,
    borders=None,
    true_values=None,
    title: str | None = None,
    ax: Axes | None = None,
) -> Figure:
    """Fig. 5 analogue: estimated points on $\\mathcal P_a$ (circles) and $\\mathcal P_d$
    (crosses), with the true borders `(f_a, f_d)` (callables) and the true limit
    cycle through `true_values` (the $2n-2$ exact $U_i$) when given."""
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
    else:
        fig = ax.figure
    levels = np.asarray(result.levels)
    n = levels.shape[0]
    if borders is not None:
        grid = np.linspace(levels[0], levels[-1], 400)
        f_a, f_d = borders
        ax.plot(grid, np.asarray(f_a(grid)), color="C0", lw=1, label="border $f_a$")
        ax.plot(grid, np.asarray(f_d(grid)), color="C3", lw=1, label="border $f_d$")
    if true_values is not None:
        cv = np.asarray(result.cycle_levels)
        tv = np.asarray(true_values)
        ax.step(
            np.r_[cv, cv[0]],
            np.r_[tv, tv[0]],
            where="post",
            color="0.6",
            lw=0.8,
            ls="--",
            label="true cycle (sampled)",
        )
    asc, desc = np.asarray(result.ascending), np.asarray(result.descending)
    ax.plot(
        asc[:, 0],
        asc[:, 1],
        "o",
        mfc="none",
        color="C0",
        ms=8,
        label=r"$\hat W_i$ on $\mathcal{P}_a$ (t < nNT$_r$)",
    )
    ax.plot(
        desc[1:-1, 0],
        desc[1:-1, 1],
        "x",
        color="C3",
        ms=8,
        label=r"$\hat W_i$ on $\mathcal{P}_d$",
    )
    ax.set_xlabel("input v (units of v)")
    ax.set_ylabel("u (units of y, G(0) = 1)")
    ax.set_title(title or f"NBBI: {2 * n - 2} points of the backlash cycle")
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_nbbi_experiment(
    t, v, y, *, w=None, axes: tuple[Axes, Axes] | None = None
) -> Figure:
    """Fig. 6 analogue: the staircase input (4a-b) above, the noisy output below."""
    from .responses import plot_input_output

    return plot_input_output(
        t,
        v,
        y,
        w=w,
        axes=axes,
        title="NBBI experiment: initialisation step, then the staircase",
    )


def _phase(g):
    """Phase in degrees on (-270, 90]: continuous for lagging plants up to order 3."""
    p = np.degrees(np.angle(g))
    return np.where(p > 90, p - 360, p)


def plot_bode(
    results: Sequence[FGIResult],
    *,
    linear=None,
    axes: tuple[Axes, Axes] | None = None,
) -> Figure:
    """Bode plot of $\\hat G_M(jk\\omega)$ (markers per base $\\omega$, Remark 2a)
    against the true $G$ (`linear.frequency_response`) when given."""
    if axes is None:
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(6.5, 5.5))
    else:
        fig = axes[0].figure
    ax_m, ax_p = axes
    all_w = []
    for i, res in enumerate(results):
        keep = np.asarray(res.keep)
        w = np.asarray(res.harmonics)[keep] * float(res.omega)
        g = np.asarray(res.g)[keep]
        all_w.append(w)
        label = rf"$\hat G_M$, $\omega$ = {float(res.omega):.3g}"
        ax_m.loglog(w, np.abs(g), "o", color=f"C{i}", mfc="none", label=label)
        ax_p.semilogx(w, _phase(g), "o", color=f"C{i}", mfc="none")
    if linear is not None and all_w:
        ws = np.concatenate(all_w)
        grid = np.logspace(np.log10(ws.min()) - 0.3, np.log10(ws.max()) + 0.3, 400)
        g = np.asarray(linear.frequency_response(grid))
        ax_m.loglog(grid, np.abs(g), "k", lw=1, label="true G")
        ax_p.semilogx(grid, _phase(g), "k", lw=1)
    ax_m.set_ylabel("|G(jw)| (y per u)")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("w (rad/s)")
    ax_m.set_title("FGI: frequency response of the linear block")
    ax_m.legend(fontsize=7, loc="best")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return fig
