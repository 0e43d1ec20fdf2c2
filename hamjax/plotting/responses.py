"""Plots of signals and of a nonlinearity's input-output characteristic."""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure


def plot_input_output(
    t, v, y, *, w=None, title: str | None = None, axes: tuple[Axes, Axes] | None = None
) -> Figure:
    """Input (top) and output (bottom) against time; `w` is the noise-free output."""
    if axes is None:
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(7, 4.5))
    else:
        fig = axes[0].figure
    ax_v, ax_y = axes
    ax_v.step(np.asarray(t), np.asarray(v), where="post", color="C0", lw=1)
    ax_v.set_ylabel("input v (units of v)")
    # The measured samples on top of the noise-free output, as points when few
    # enough to see, so neither hides the other.
    few = np.size(t) <= 600
    if w is not None:
        ax_y.plot(np.asarray(t), np.asarray(w), color="k", lw=1, label="noise-free w")
    ax_y.plot(
        np.asarray(t),
        np.asarray(y),
        color="C1",
        lw=0 if few else 0.6,
        marker="." if few else None,
        ms=4,
        alpha=0.9,
        label="measured y",
        zorder=3,
    )
    if w is not None:
        ax_y.legend(loc="best", fontsize=8)
    ax_y.set_ylabel("output y (units of y)")
    ax_y.set_xlabel("t (s)")
    if title:
        ax_v.set_title(title)
    fig.tight_layout()
    return fig


def plot_characteristic(
    v, u, *, borders=None, grid=None, title: str | None = None, ax: Axes | None = None
) -> Figure:
    """The working point $(v, u)$ traced by a signal, with optional border curves.

    `borders` is `(f_a, f_d)` callables evaluated on `grid`.
    """
    if ax is None:
        fig, ax = plt.subplots(figsize=(5, 4.5))
    else:
        fig = ax.figure
    if borders is not None and grid is not None:
        g = np.asarray(grid)
        ax.plot(g, np.asarray(borders[0](g)), color="C2", lw=1, label="ascending $f_a$")
        ax.plot(
            g, np.asarray(borders[1](g)), color="C3", lw=1, label="descending $f_d$"
        )
    ax.plot(np.asarray(v), np.asarray(u), color="k", lw=1.2, label="working point")
    ax.set_xlabel("input v (units of v)")
    ax.set_ylabel("u = F[v] (units of u)")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig
