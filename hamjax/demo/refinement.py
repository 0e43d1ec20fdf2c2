"""Demo section: closed form vs refined (optimistix) vs Cramér-Rao bound, seed 001."""

from pathlib import Path

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
    fig = plot_closed_form_vs_refined(
        names, truth, _flat(closed_dict), _flat(refined["refined"]), se
    )
    fig.axes[0].set_title(
        "Piecewise-linear plant, 1400 samples, noise std 0.5: closed form vs refined"
    )
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
        },
    )
    return [
        (
            "refinement_closed_vs_refined.png",
            "per parameter, the error of the batch "
            "least-squares closed form and of the output-error refinement, in units of "
            "the Cramér-Rao standard deviation (grey band: +-2)",
        ),
        ("refinement.json", "the numbers behind the figure"),
    ]
