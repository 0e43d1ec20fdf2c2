"""Seed 001, Section V.C reproduced noise-free: Theta*, the normalised-gradient run
(4.1) on the impulse input (5.1), convergence times, and the Fig. 3a/3b analogues.

Used by `hamjax reproduce recursive-pl` and by the demo.
"""

from pathlib import Path

import numpy as np

from ...identification.seed001 import (
    STRUCTURES,
    identify_recursive_pl,
    recover_history,
    recover_parameters,
)
from ...io import write_json
from ...signals import pe_impulse_sequence
from ...simulation import simulate
from .plants import paper_case


def samples_to_tolerance(errors: np.ndarray, tol: float) -> int | None:
    """Samples after which `errors[t] <= tol` for good (None if never)."""
    above = np.nonzero(np.asarray(errors) > tol)[0]
    if above.size == 0:
        return 0
    last = int(above[-1])
    return None if last == errors.shape[0] - 1 else last + 1


def reproduce_section_vc(*, periods: int = 2000):
    """Section V.C noise-free: Theta*, the gradient run and its convergence times.

    **Returns:** `(summary dict, RecursivePLResult, RecursivePLCase, the
    parameters recovered from every estimate of the history)`.
    """
    case = paper_case()
    _, v = pe_impulse_sequence(case.levels, order=2, periods=periods)
    y = simulate(case.plant(), v)
    res = identify_recursive_pl(v, y, levels=case.levels, order=2)
    theta_star = np.asarray(case.theta_star())
    printed = [0.56, -1.5, 1.66, -3.33, 1.33, -2.66, 1, -2, 1, -2]
    in_print_order = np.r_[theta_star[1], theta_star[0], theta_star[2:]]
    theta_err = np.abs(np.asarray(res.history) - theta_star).max(axis=1)
    hist = recover_history(res)
    truth = case.normalised_truth()
    phys = np.max(
        np.stack(
            [
                np.abs(np.asarray(getattr(hist, k)) - np.asarray(truth[k]))
                .reshape(theta_err.shape[0], -1)
                .max(axis=1)
                for k in ("a", "b", "d", "points", "k1", "k2", "h1", "h2")
            ]
        ),
        axis=0,
    )
    counts = {
        f"{name}_{tol:g}": samples_to_tolerance(err, tol)
        for name, err in (("theta", theta_err), ("physical", phys))
        for tol in (1e-3, 1e-6)
    }
    e = res.estimate
    # What each rule of (3.18) makes of the paper's (non-dead-zone, non-preload,
    # non-symmetric) map: the four points cannot identify D and L here.
    rules = {}
    for s in STRUCTURES:
        r = recover_parameters(res.theta, levels=case.levels, order=2, structure=s)
        rules[s] = {k: float(getattr(r, k)) for k in ("d1", "d2", "l1", "l2")} | {
            "consistent": bool(r.consistent)
        }
    summary = {
        "plant": "A = 1 - 1.5 q^-1 + 0.56 q^-2, B = q^-1 - 2 q^-2, K = (1, 2), "
        "D = (1, -2), L = (1, -2), V = (-6, -3, 3, 6), z = 0",
        "theta_star": theta_star.tolist(),
        "theta_star_in_paper_print_order": in_print_order.tolist(),
        "theta_star_paper_print": printed,
        "max_abs_difference_to_print": float(np.max(np.abs(in_print_order - printed))),
        "samples": int(y.shape[0]),
        "samples_to_tolerance": counts,
        "final_theta_error": float(theta_err[-1]),
        "estimate": {
            "a": np.asarray(e.a).tolist(),
            "b": np.asarray(e.b).tolist(),
            "points": np.asarray(e.points).tolist(),
            "k1": float(e.k1),
            "k2": float(e.k2),
            "h1": float(e.h1),
            "h2": float(e.h2),
        },
        "truth_normalised_3_10": {k: np.asarray(x).tolist() for k, x in truth.items()},
        "rules_3_18_on_paper_map": rules,
    }
    summary["headline"] = [
        "theta* (paper print order a2, a1, mu..): "
        + " ".join(f"{x:.4g}" for x in in_print_order),
        f"samples to 1e-3 / 1e-6 (max |theta - theta*|): {counts['theta_0.001']} / "
        f"{counts['theta_1e-06']}; physical (a, b, F(Vj), K, H): "
        f"{counts['physical_0.001']} / {counts['physical_1e-06']}",
    ]
    return summary, res, case, hist


def write_section_vc(
    out: Path, *, periods: int = 2000, prefix: str = "", dpi: int = 120
) -> tuple[dict, list[tuple[str, str]]]:
    """Run `reproduce_section_vc` and write its figures and JSON into `out`.

    **Returns:** `(summary, [(file name, description), ...])`.
    """
    from ...plotting.recursive_pl import plot_convergence, plot_fig3a, plot_fig3b

    summary, res, case, hist = reproduce_section_vc(periods=periods)
    t = np.arange(res.history.shape[0])
    names = [prefix + n for n in ("fig3a.png", "fig3b.png", "convergence.png")]
    plot_fig3a(t, res.history, case.theta_star()).savefig(out / names[0], dpi=dpi)
    plot_fig3b(t, hist, case).savefig(out / names[1], dpi=dpi)
    plot_convergence(t, res.history, hist, case).savefig(out / names[2], dpi=dpi)
    write_json(out / f"{prefix}reproduce.json", summary)
    made = [
        (
            names[0],
            "normalised-gradient estimates of Theta against t, "
            "converging to Theta* (analogue of seed 001 Fig. 3a)",
        ),
        (names[1], "the nonlinearity's parameters against t (Fig. 3b analogue)"),
        (names[2], "max |Theta-hat - Theta*| against t, log scale"),
        (
            f"{prefix}reproduce.json",
            "Theta*, final estimates, samples to 1e-3 and 1e-6",
        ),
    ]
    return summary, made
