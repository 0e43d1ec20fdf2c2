"""Demo section: seed 001's Section V.C reproduced (Fig. 3a/3b analogues)."""

from pathlib import Path

import numpy as np

from ...cli.methods.recursive_pl import reproduce_section_vc
from ...identification.recursive_pl import recover_history
from ...io import write_json
from ...plotting.recursive_pl import plot_convergence, plot_fig3a, plot_fig3b


def run(key, out: Path) -> list[tuple[str, str]]:
    del key  # noise-free, as in the paper
    summary, res, case = reproduce_section_vc(periods=1200)
    t = np.arange(res.history.shape[0])
    hist = recover_history(res)
    plot_fig3a(t, res.history, case.theta_star()).savefig(
        out / "seed001_fig3a.png", dpi=110
    )
    plot_fig3b(t, hist, case).savefig(out / "seed001_fig3b.png", dpi=110)
    plot_convergence(t, res.history, hist, case).savefig(
        out / "seed001_convergence.png", dpi=110
    )
    write_json(out / "seed001_reproduce.json", summary)
    return [
        (
            "seed001_fig3a.png",
            "normalised-gradient estimates of Theta against t, "
            "converging to Theta* (analogue of seed 001 Fig. 3a)",
        ),
        (
            "seed001_fig3b.png",
            "the nonlinearity's parameters against t (Fig. 3b analogue)",
        ),
        ("seed001_convergence.png", "max |Theta-hat - Theta*| against t, log scale"),
        ("seed001_reproduce.json", "Theta*, final estimates, samples to 1e-3 and 1e-6"),
    ]
