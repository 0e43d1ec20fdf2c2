"""Demo section: closed form vs refined (optimistix) vs Cramér-Rao bound, for seed
001's batch least squares (left panel) and seed 000's NBBI + FGI (right panel)."""

from pathlib import Path

import jax.random as jr
import numpy as np

from .. import models as hm, signals, simulation
from ..identification import identify_recursive_pl
from ..io import write_json
from ..io.results import recursive_pl_result_dict
from ..papers.seed001.plants import paper_case, seed001_plant
from ..plotting.refinement import plot_closed_form_vs_refined
from ..refinement import refine_recursive_pl_result


def _flat(d: dict) -> np.ndarray:
    return np.concatenate([d["a"], d["b"], np.asarray(d["points"])[:, 1]])


def run(key, out: Path) -> list[tuple[str, str]]:
    plant, levels, order = seed001_plant()
    _, v = signals.pe_impulse_sequence(levels, order=order, periods=100)
    w = simulation.simulate(plant, v)
    y = hm.add_noise(key, w, hm.WhiteNoise(0.5))
    closed = identify_recursive_pl(
        v, y, levels=levels, order=order, estimator="batch", keep_history=False
    )
    closed_dict = recursive_pl_result_dict(closed, rho=1e6, estimator="batch")
    refined = refine_recursive_pl_result(v, y, closed_dict, levels=levels, order=order)
    t = paper_case().normalised_truth()  # the truth in the (3.10) normalisation
    truth = np.concatenate([t["a"], t["b"], t["points"]])
    se_points = np.asarray(refined["standard_errors"]["points"], dtype=float)
    se = np.concatenate(
        [
            refined["standard_errors"]["a"],
            refined["standard_errors"]["b"],
            se_points[:, 1] if se_points.ndim == 2 else se_points,
        ]
    )
    names = ["a1", "a2", "b1", "b2"] + [f"F(V{j})" for j in range(1, 5)]
    import matplotlib.pyplot as plt

    fig, (ax_pl, ax_fgi) = plt.subplots(
        1, 2, figsize=(12.5, 3.6), gridspec_kw={"width_ratios": [8, 14]}
    )
    plot_closed_form_vs_refined(
        names, truth, _flat(closed_dict), _flat(refined["refined"]), se, ax=ax_pl
    )
    ax_pl.set_title("Piecewise-linear plant (1400 samples, noise std 0.5)", fontsize=9)
    fgi = _fgi_panel(jr.fold_in(key, 1), ax_fgi)
    fig.tight_layout()
    fig.savefig(out / "refinement_closed_vs_refined.png", dpi=110)
    write_json(
        out / "refinement.json",
        {
            "names": names,
            "truth": truth,
            "closed_form": _flat(closed_dict),
            "refined": _flat(refined["refined"]),
            "standard_errors": se,
            "converged": refined["converged"],
            "fgi": fgi,
        },
    )
    return [
        (
            "refinement_closed_vs_refined.png",
            "per parameter, the error of the closed form and of the output-error "
            "refinement in units of the Cramér-Rao standard deviation (grey band: "
            "+-2): seed 001's batch least squares (left), seed 000's NBBI + FGI, the "
            "border points and G(jk w) at two frequencies (right)",
        ),
        ("refinement.json", "the numbers behind the figure"),
    ]


def _fgi_panel(key, ax) -> dict:
    """Seed 000's Fig. 6 plant: NBBI (plain average (5)) then FGI at two
    frequencies, against their joint output-error refinement, on one noisy draw."""
    import jax.numpy as jnp

    from ..papers.seed000.plants import seed000_plant
    from ..papers.seed000.studies.refinement_fgi import closed_form, make_design
    from ..refinement import cramer_rao_bound, refine

    plant, levels, _, _ = seed000_plant()
    d = make_design(
        plant,
        levels,
        hold=20.0,
        dt=0.05,
        omegas=[0.5, 1.8],
        periods=8,
        settle_fraction=0.5,
    )
    p, sigma = d.parametrisation, 0.08
    k1, k2 = jr.split(key)
    yn = d.w_nbbi + sigma * jr.normal(k1, d.w_nbbi.shape)
    yf = d.w_fgi + sigma * jr.normal(k2, d.w_fgi.shape)
    lv = tuple(float(x) for x in levels)
    theta_cf, _ = closed_form(
        p, yn, yf, levels=lv, nbbi_start=d.nbbi_start, settled=False
    )
    y = p.select(yn, yf)
    res = refine(p, p.initial_theta(yn, yf), y, y, throw=False)
    samples = p.select(d.w_nbbi, d.w_fgi)
    se = np.sqrt(np.diag(np.asarray(cramer_rao_bound(p, d.truth, samples, sigma))))
    truth = np.asarray(d.truth)
    plot_closed_form_vs_refined(
        list(p.names), truth, np.asarray(theta_cf), np.asarray(res.estimate), se, ax=ax
    )
    ax.set_title(
        "Backlash plant: NBBI + FGI (hold 20 s, 8 periods at 0.5 and 1.8 rad/s, "
        "noise std 0.08)",
        fontsize=9,
    )
    return {
        "names": list(p.names),
        "truth": truth,
        "closed_form": np.asarray(theta_cf),
        "refined": np.asarray(jnp.asarray(res.estimate)),
        "crlb_std": se,
    }
