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
    ax.set_xlabel("input v (units of v)")
    ax.set_ylabel("residual y - y_nominal (units of y)")
    ax.set_title("validation residual against the input and its direction")
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
    ax.set_ylabel("periodogram |FFT|²/N (units of y²)")
    ax.set_title("spectrum of the validation residual")
    ax.legend(fontsize=8)
    return fig


def plot_validation(d, ax: Axes | None = None, *, name: str = "case") -> Figure:
    """Measured validation output against the nominal and the augmented model, the
    case and its gaps in the title."""
    fig, ax = _axes(ax)
    ax.plot(d.t, d.y, color="0.5", lw=0.8, label="measured")
    ax.plot(d.t, d.y_nominal, lw=0.8, label=f"nominal (gap {d.gap_before:.3g})")
    ax.plot(
        d.t,
        d.y_augmented,
        lw=0.8,
        ls="--",
        label=f"nominal + {d.effect} (gap {d.gap_after:.3g})",
    )
    ax.set_xlabel("t (s)")
    ax.set_ylabel("y (units of y)")
    ax.set_title(
        f"{name}: validation record (noise floor {d.noise_floor:.3g})", fontsize=10
    )
    ax.legend(fontsize=8)
    return fig


def plot_ranking(d, ax: Axes | None = None) -> Figure:
    """Validation gap after each candidate against the gap before and the noise
    floor: simulation errors and one-step prediction errors (the noise models) on
    separate axes, since the two measure different things."""
    groups = [
        (m, [c for c in d.ranking if (c["measure"] == "simulation") == (m == 0)])
        for m in (0, 1)
    ]
    groups = [(m, cs) for m, cs in groups if cs]
    if ax is None:
        heights = [max(len(cs), 1) for _, cs in groups]
        fig, axes = plt.subplots(
            len(groups),
            1,
            figsize=(6.4, 1.2 + 0.32 * sum(heights)),
            gridspec_kw={"height_ratios": heights},
            squeeze=False,
        )
        axes = list(axes[:, 0])
    else:
        fig, axes = ax.figure, [ax] * len(groups)
    for a, (m, cs) in zip(axes, groups, strict=True):
        y = np.arange(len(cs))[::-1]
        a.barh(y, [c["gap_after"] for c in cs], color="C0" if m == 0 else "C1")
        a.set_yticks(y, [c["effect"] for c in cs], fontsize=8)
        a.axvline(d.noise_floor, color="C2", ls="--", label="noise floor")
        if m == 0:
            a.axvline(d.gap_before, color="k", label="gap before (nominal)")
            a.set_xlabel("validation RMS simulation error (units of y)")
        else:
            a.set_xlabel("validation RMS one-step prediction error (units of y)")
        a.legend(fontsize=7)
    axes[0].set_title(f"candidates (named: {d.effect})")
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


def plot_reliability(calibration: dict, ax: Axes | None = None) -> Figure:
    """Reliability diagram: per confidence bin, the accuracy of the diagnoses against
    their mean stated probability (the diagonal is perfect calibration)."""
    fig, ax = _axes(ax)
    bins = calibration["bins"]
    conf = [b["mean_confidence"] for b in bins]
    acc = [b["accuracy"] for b in bins]
    size = [20 + 4 * b["cases"] ** 0.75 for b in bins]
    ax.plot([0, 1], [0, 1], color="0.6", lw=0.8, ls="--", label="calibrated")
    ax.plot(conf, acc, color="C0", lw=1)
    ax.scatter(conf, acc, s=size, color="C0", zorder=3, label="bins (area: cases)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("stated probability of the named effect")
    ax.set_ylabel("fraction named correctly")
    ax.set_title(f"reliability (ECE {calibration['ece']:.3f})")
    ax.legend(fontsize=8, loc="upper left")
    return fig


def save_diagnosis_figures(d, out: Path, name: str = "case") -> list[Path]:
    """Write the four figures of a diagnosis of case `name` into `out`."""
    paths = []
    for file, fn in (
        ("residual_amplitude.png", plot_residual_amplitude),
        ("residual_spectrum.png", plot_residual_spectrum),
        ("validation.png", lambda d: plot_validation(d, name=name)),
        ("ranking.png", plot_ranking),
    ):
        fig = fn(d)
        fig.tight_layout()
        fig.savefig(Path(out) / file, dpi=110)
        plt.close(fig)
        paths.append(Path(out) / file)
    return paths
