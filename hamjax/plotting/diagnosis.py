"""Figures of a gap diagnosis (`GapDiagnosis`) and of a blind-benchmark score."""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure


def _axes(ax: Axes | None) -> tuple[Figure, Axes]:
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        return fig, ax
    return ax.figure, ax


def plot_residual_amplitude(d, ax: Axes | None = None) -> Figure:
    """Validation residual against the input, rising and falling marked."""
    fig, ax = _axes(ax)
    dv = np.sign(np.diff(d.v, prepend=d.v[0]))
    for s, label, c in (
        (1, "rising", "C3"),
        (-1, "falling", "C0"),
        (0, "steady", "0.6"),
    ):
        sel = dv == s
        ax.plot(d.v[sel], d.residual_before[sel], ".", ms=2, color=c, label=label)
    ax.axhspan(
        -2 * d.noise_floor, 2 * d.noise_floor, color="C2", alpha=0.15, label="±2 noise"
    )
    ax.set_xlabel("input v")
    ax.set_ylabel("residual y - y_nominal")
    ax.set_title("residual vs amplitude and direction")
    ax.legend(fontsize=8)
    return fig


def plot_residual_spectrum(d, ax: Axes | None = None) -> Figure:
    """Periodograms of the residual before and after, against the noise floor."""
    fig, ax = _axes(ax)
    dt = float(d.t[1] - d.t[0])
    n = d.t.shape[0]
    f = np.fft.rfftfreq(n, dt)[1:]
    for r, label in (
        (d.residual_before, "nominal"),
        (d.residual_after, f"+ {d.effect}"),
    ):
        P = np.abs(np.fft.rfft(r - r.mean()))[1:] ** 2 / n
        ax.loglog(f, P, lw=0.7, label=label)
    ax.axhline(d.noise_floor**2, color="k", ls="--", label="noise floor")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("periodogram")
    ax.set_title("residual spectrum")
    ax.legend(fontsize=8)
    return fig


def plot_validation(d, ax: Axes | None = None) -> Figure:
    """Measured validation output against the nominal and the augmented model."""
    fig, ax = _axes(ax)
    ax.plot(d.t, d.y, color="0.5", lw=0.8, label="measured")
    ax.plot(d.t, d.y_nominal, lw=0.8, label="nominal")
    ax.plot(d.t, d.y_augmented, lw=0.8, ls="--", label=f"nominal + {d.effect}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("y")
    ax.set_title("validation record")
    ax.legend(fontsize=8)
    return fig


def plot_ranking(d, ax: Axes | None = None) -> Figure:
    """Validation gap after each candidate, with the gap before and the noise floor."""
    fig, ax = _axes(ax)
    names = [c["effect"] for c in d.ranking]
    gaps = [c["gap_after"] for c in d.ranking]
    colours = ["C1" if c["measure"] != "simulation" else "C0" for c in d.ranking]
    y = np.arange(len(names))[::-1]
    ax.barh(y, gaps, color=colours)
    ax.set_yticks(y, names, fontsize=8)
    ax.axvline(d.gap_before, color="k", label="gap before")
    ax.axvline(d.noise_floor, color="C2", ls="--", label="noise floor")
    ax.set_xlabel("validation RMS (orange: one-step prediction)")
    ax.set_title(f"candidates (named: {d.effect})")
    ax.legend(fontsize=8)
    return fig


def plot_confusion(score: dict, ax: Axes | None = None) -> Figure:
    """Blind-benchmark confusion matrix (rows truth, columns named)."""
    fig, ax = _axes(ax)
    truth = [t for t in score["confusion"] if sum(score["confusion"][t].values())]
    named = list(next(iter(score["confusion"].values())))
    M = np.array([[score["confusion"][t][p] for p in named] for t in truth])
    ax.imshow(M, cmap="Blues")
    ax.set_xticks(range(len(named)), named, rotation=90, fontsize=7)
    ax.set_yticks(range(len(truth)), truth, fontsize=7)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            if M[i, j]:
                ax.text(j, i, str(M[i, j]), ha="center", va="center", fontsize=6)
    ax.set_title(
        f"accuracy {score['accuracy']:.3f}, false alarm {score['false_alarm_none']:.3f}"
    )
    return fig


def save_diagnosis_figures(d, out: Path) -> list[Path]:
    """Write the four figures of a diagnosis into `out`."""
    paths = []
    for name, fn in (
        ("residual_amplitude.png", plot_residual_amplitude),
        ("residual_spectrum.png", plot_residual_spectrum),
        ("validation.png", plot_validation),
        ("ranking.png", plot_ranking),
    ):
        fig = fn(d)
        fig.tight_layout()
        fig.savefig(Path(out) / name, dpi=110)
        plt.close(fig)
        paths.append(Path(out) / name)
    return paths
