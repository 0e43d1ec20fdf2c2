"""Figures of the refinement studies: closed form vs refined vs Cramér-Rao bound."""

import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter


def plot_refinement_study(summary: dict, *, which: str = "rmse") -> Figure:
    """One panel per parameter, against the record length (samples).

    - `which="rmse"`: RMSE of the closed form (dashed) and the refined estimate
      (solid) per SNR, with $\\sqrt{\\text{CRLB}}$ (dotted, same colour).
    - `which="efficiency"`: $\\text{CRLB}/\\text{MSE}$ of both, with 95% intervals,
      and the 0.8 target.

    **Arguments:** `summary`, the dict written by a `refinement-*` study (keys
    `parameters` and `configs`, each config with `samples`, `snr_db`,
    `closed_form`, `refined`).
    """
    if which not in ("rmse", "efficiency"):
        raise ValueError(f"which must be 'rmse' or 'efficiency'; got {which!r}")
    names = summary["parameters"]
    configs = summary["configs"]
    snrs = sorted({c["snr_db"] for c in configs})
    cols = min(4, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False
    )
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, name in enumerate(names):
        ax = axes[i // cols][i % cols]
        for s, snr in enumerate(snrs):
            cs = sorted(
                (c for c in configs if c["snr_db"] == snr), key=lambda c: c["samples"]
            )
            x = np.array([c["samples"] for c in cs], dtype=float)
            colour = colours[s % len(colours)]
            for key, style, label in (
                ("closed_form", "--", "closed form"),
                ("refined", "-", "refined"),
            ):
                if key not in cs[0]:
                    continue
                if which == "rmse":
                    y = np.array([c[key]["rmse"][i] for c in cs], dtype=float)
                    ax.loglog(
                        x,
                        y,
                        style,
                        color=colour,
                        marker="o",
                        ms=3,
                        label=f"{label}, {snr:g} dB",
                    )
                else:
                    y = np.array([c[key]["efficiency"][i] for c in cs], dtype=float)
                    lo = np.array(
                        [c[key]["efficiency_ci"][0][i] for c in cs], dtype=float
                    )
                    hi = np.array(
                        [c[key]["efficiency_ci"][1][i] for c in cs], dtype=float
                    )
                    ax.errorbar(
                        x,
                        y,
                        # A tiny R leaves the upper end unbounded (MSE - 1.96 MCSE
                        # <= 0): clip it to the axis, which stops at 1.3.
                        yerr=[np.clip(y - lo, 0, 10), np.clip(hi - y, 0, 10)],
                        fmt=style,
                        color=colour,
                        marker="o",
                        ms=3,
                        capsize=2,
                        label=f"{label}, {snr:g} dB",
                    )
                    ax.set_xscale("log")
            if which == "rmse":
                bound = np.array([c["refined"]["crlb_std"][i] for c in cs], dtype=float)
                ax.loglog(
                    x,
                    bound,
                    ":",
                    color="k" if s == 0 else colour,
                    lw=1.5,
                    label=f"sqrt(CRLB), {snr:g} dB",
                )
        if which == "efficiency":
            ax.axhline(0.8, color="0.5", lw=0.8, ls=":")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.set_ylim(0.0, 1.3)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(name, fontsize=9)
        ax.grid(alpha=0.3, which="both")
        if i // cols == rows - 1:
            ax.set_xlabel("samples N")
    for j in range(len(names), rows * cols):
        axes[j // cols][j % cols].axis("off")
    axes[0][0].legend(fontsize=6)
    title = "RMSE vs sqrt(CRLB)" if which == "rmse" else "efficiency CRLB / MSE"
    fig.suptitle(
        f"{summary.get('study', 'refinement')}: {title} "
        f"(R = {summary.get('realisations', '?')})",
        fontsize=10,
    )
    fig.tight_layout()
    return fig


def plot_closed_form_vs_refined(
    names, truth, closed_form, refined, standard_errors, *, ax=None
) -> Figure:
    """Per parameter: error of the closed form and of the refined estimate, with the
    refined estimate's $\\pm 2$ standard errors (Fisher information) around zero.

    All arrays have shape `(p,)`; errors are divided by the standard errors so
    parameters of different scales share the axis.
    """
    truth, closed_form, refined, se = (
        np.asarray(x, dtype=float)
        for x in (truth, closed_form, refined, standard_errors)
    )
    if ax is None:
        fig, ax = plt.subplots(figsize=(max(4.0, 0.6 * len(names) + 2), 3.2))
    else:
        fig = ax.figure
    x = np.arange(len(names))
    z_closed, z_refined = (closed_form - truth) / se, (refined - truth) / se
    ax.axhspan(-2, 2, color="0.85", label="+-2 standard errors (CRLB)")
    ax.plot(x - 0.1, z_closed, "s", label="closed form")
    ax.plot(x + 0.1, z_refined, "o", label="refined")
    ax.axhline(0, color="k", lw=0.8)
    # Linear within +-3 standard errors, logarithmic beyond: one far outlier no
    # longer flattens the points that sit inside the band.
    top = np.nanmax(np.abs(np.r_[z_closed, z_refined]), initial=0.0)
    if top > 6:
        ax.set_yscale("symlog", linthresh=3.0)
        ticks = [2.0] + [10.0**k for k in range(1, int(np.log10(top)) + 2)]
        ticks = sorted([0.0] + [s * x for x in ticks for s in (-1, 1)])
        ax.set_yticks(ticks, [f"{x:g}" for x in ticks])
    ax.set_xticks(x, names, rotation=45, fontsize=8)
    ax.set_ylabel("error / standard error")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def save_refinement_study(summary: dict, out, stem: str) -> None:
    """Write `<stem>_rmse.png`, `<stem>_efficiency.png` and `<stem>.json` into `out`."""
    from pathlib import Path

    from ..io import write_json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for which in ("rmse", "efficiency"):
        fig = plot_refinement_study(summary, which=which)
        fig.savefig(out / f"{stem}_{which}.png", dpi=110)
        plt.close(fig)
    write_json(out / f"{stem}.json", summary)
