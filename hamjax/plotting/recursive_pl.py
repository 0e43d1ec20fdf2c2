"""Figures of seed 001: the Fig. 3a/3b analogues and the Monte Carlo studies."""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure


def _axes(ax):
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 4))
        return fig, ax
    return ax.figure, ax


def theta_labels(order: int) -> list[str]:
    """Names of the entries of $\\Theta$ in the order (3.8c)."""
    a = [f"a{i + 1}" for i in range(order)]
    mu = [f"mu{i + 1}{j + 1}" for j in range(4) for i in range(order)]
    return a + mu


def plot_fig3a(t, history, theta_star, *, ax=None) -> Figure:
    """Fig. 3a analogue: every $\\hat\\Theta_k(t)$ with its true value (dashed)."""
    own_figure = ax is None
    fig, ax = _axes(ax)
    history = np.asarray(history)
    theta_star = np.asarray(theta_star)
    labels = theta_labels(history.shape[1] // 5)
    for k in range(history.shape[1]):
        (line,) = ax.plot(np.asarray(t) + 1, history[:, k], lw=1, label=labels[k])
        ax.axhline(theta_star[k], color=line.get_color(), ls="--", lw=0.7)
    ax.set_xscale("log")
    ax.set_xlabel("t + 1 (samples)")
    ax.set_ylabel("parameter estimate")
    ax.set_title("Recursive estimates of the parameter vector (true values dashed)")
    # Outside the axes: inside, any corner hides a curve or its target.
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    if own_figure:  # room for the legend beside the axes
        fig.set_size_inches(8.2, 4)
    fig.tight_layout()
    return fig


def plot_fig3b(t, estimates, case, *, ax=None) -> Figure:
    """Fig. 3b analogue: $\\hat K_1, \\hat K_2, \\hat H_1, \\hat H_2$ against t, in the
    plant's own scale ($b_1 = 1$: the estimates of (3.10) times $\\hat b_1$)."""
    fig, ax = _axes(ax)
    f = case.nonlinearity
    scale = np.asarray(estimates.b)[:, 0] / float(case.b[0])
    truth = {
        "K1": float(f.k1),
        "K2": float(f.k2),
        "H1": float(f.l1 - f.k1 * f.d1),
        "H2": float(f.l2 - f.k2 * f.d2),
    }
    for name, field in (("K1", "k1"), ("K2", "k2"), ("H1", "h1"), ("H2", "h2")):
        y = np.asarray(getattr(estimates, field)) * scale
        (line,) = ax.plot(np.asarray(t) + 1, y, label=name)
        ax.axhline(truth[name], color=line.get_color(), ls="--", lw=0.7)
    ax.set_xscale("log")
    ax.set_ylim(-6, 6)
    ax.set_xlabel("t + 1 (samples)")
    ax.set_ylabel("slope K, offset H (units of u per v, of u)")
    ax.set_title("Recursive estimates of the map's slopes and offsets (truth dashed)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_convergence(t, history, estimates, case, *, ax=None) -> Figure:
    """Max-abs error of $\\hat\\Theta(t)$ and of $(\\hat b, \\hat F(V_j), \\hat K,
    \\hat H)$ (normalisation (3.10)) against t, log scale."""
    fig, ax = _axes(ax)
    theta_err = np.abs(np.asarray(history) - np.asarray(case.theta_star())).max(1)
    truth = case.normalised_truth()
    phys = np.max(
        [
            np.abs(np.asarray(getattr(estimates, k)) - np.asarray(truth[k]))
            .reshape(len(t), -1)
            .max(1)
            for k in ("b", "points", "k1", "k2", "h1", "h2")
        ],
        axis=0,
    )
    ax.semilogy(t, theta_err, label="max |theta - theta*|")
    ax.semilogy(t, phys, label="max error of b, F(Vj), K, H (3.10)")
    for tol in (1e-3, 1e-6):
        ax.axhline(tol, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("t (samples)")
    ax.set_ylabel("max absolute error")
    ax.set_title("Convergence of the recursive estimates")
    ax.legend()
    fig.tight_layout()
    return fig


def plot_curves(
    x,
    curves: dict,
    *,
    xlabel: str,
    ylabel: str,
    title: str,
    logx: bool = False,
    logy: bool = True,
    bands: dict | None = None,
    dots: bool = False,
    ax=None,
) -> Figure:
    """Generic study plot: one series per entry of `curves` (name -> y values), a
    line with markers and optional `bands` (name -> (low, high)) shaded, or with
    `dots` a scatter of per-realisation values (`x` may then be a dict too, name ->
    x values). The y axis is logarithmic if `logy` and some value is > 0."""
    fig, ax = _axes(ax)
    for name, y in curves.items():
        xs = x[name] if isinstance(x, dict) else x
        if dots:
            ax.scatter(np.asarray(xs), np.asarray(y), s=4, alpha=0.5, label=name)
            continue
        (line,) = ax.plot(xs, y, marker="o", ms=3, label=name)
        if bands and name in bands:
            lo, hi = bands[name]
            ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
    values = np.concatenate(
        [np.ravel(np.asarray(y, dtype=float)) for y in curves.values()]
    )
    if logx:
        ax.set_xscale("log")
    if logy and np.any(np.isfinite(values) & (values > 0)):
        ax.set_yscale("log")
    return _labelled(fig, ax, xlabel, ylabel, title, markerscale=3 if dots else 1)


def _labelled(fig, ax, xlabel: str, ylabel: str, title: str, **legend) -> Figure:
    """The study plots' axis labels, small title and legend, laid out."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, **legend)
    fig.tight_layout()
    return fig


def plot_histogram(
    samples: dict, *, xlabel: str, title: str, logx: bool = True, ax=None
) -> Figure:
    """Histograms of per-realisation values (name -> array), log bins if `logx`."""
    fig, ax = _axes(ax)
    finite = [
        np.asarray(s)[np.isfinite(s) & (np.asarray(s) > 0 if logx else True)]
        for s in samples.values()
    ]
    lo = min((f.min() for f in finite if f.size), default=1.0)
    hi = max((f.max() for f in finite if f.size), default=10.0)
    bins = np.geomspace(lo, hi * 1.001, 40) if logx else np.linspace(lo, hi, 40)
    for (name, _), f in zip(samples.items(), finite, strict=True):
        ax.hist(f, bins=bins, alpha=0.5, label=name)
    if logx:
        ax.set_xscale("log")
    return _labelled(fig, ax, xlabel, "realisations", title)
