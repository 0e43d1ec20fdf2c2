"""What the seed-000 studies share: the test plant and levels, common options, and
the way a study closes (figure, verdict, JSON)."""

from pathlib import Path

from ...._argtypes import positive_float
from ....identification.seed000.nbbi_table1 import identify_nbbi
from ....io import write_json
from ....models import ContinuousTransferFunction, Hammerstein
from ....montecarlo.registry import StudyOption
from ..border_shapes import straight


# n = 4 levels on [-1, 1] and a straight backlash of width 0.4 before
# G(s) = 1 / (0.25 s^2 + s + 1) (unit static gain, settles in ~ 5 s).
LEVELS = (-1.0, -1.0 / 3.0, 1.0 / 3.0, 1.0)
DT = StudyOption("dt", 0.05, "sampling period (0.05)", positive_float)
OMEGA = StudyOption("omega", 1.0, "base omega (1.0)", positive_float)


def noise_option(default: float) -> StudyOption:
    """`--noise`: the output noise std."""
    return StudyOption("noise", default, f"noise std ({default:g})", float)


def study_linear() -> ContinuousTransferFunction:
    return ContinuousTransferFunction([1.0], [0.25, 1.0, 1.0])


def study_plant() -> Hammerstein:
    """The straight backlash of width 0.4 before `study_linear()`."""
    return Hammerstein(straight(0.4), study_linear())


def settled_nbbi(y, levels, *, hold: float, dt: float, start: int):
    """NBBI (Table 1) averaging each hold's second half only (the settled average),
    with failures returned as values (`throw=False`)."""
    return identify_nbbi(
        y, levels, hold=hold, dt=dt, start=start, discard=hold / 2, throw=False
    )


def close_study(fig, ax, out, name: str, summary: dict, verdict: list[str]) -> dict:
    """Finish the figure (legend, grid), write `name.png` and `name.json` with the
    verdict and headline in the summary, and return the summary."""
    import matplotlib.pyplot as plt

    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(Path(out) / f"{name}.png", dpi=110)
    plt.close(fig)
    summary["verdict"] = verdict
    summary["headline"] = "; ".join(verdict)
    write_json(Path(out) / f"{name}.json", summary)
    return summary
