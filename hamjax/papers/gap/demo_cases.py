"""Small withheld-effect cases for tests, the demo and docs (not a stable API)."""

import jax.random as jr
import numpy as np

from ...models import DiscreteTransferFunction, Hammerstein, Identity
from .blind import _lfilter, _Truth


DT = 0.05


def nominal() -> Hammerstein:
    """The nominal model of every demo case. Built on each call, not when this
    module is imported: its arrays then take the precision in force (float64 once
    `hamjax.enable_x64` has run, whatever the order of the imports)."""
    return Hammerstein(
        Identity(), DiscreteTransferFunction([0.0, 0.2, 0.1], [1.0, -1.1, 0.4], DT)
    )


# textbook-form parameters of each effect on the nominal above (inputs in [-1, 1])
EXACT_PARAMS = {
    "backlash": {"c": 0.3},
    "dead_zone": {"w_lo": 0.2, "w_hi": 0.2},
    "saturation": {"lo": -0.5, "hi": 0.6},
    "preload": {"c": 0.2},
    "rate_limit": {"r": 4.0},
    "time_delay": {"tau": 3.0},
    "extra_pole": {"p": 0.7},
    "output_nonlinearity": {"shape": "quadratic", "a": 0.3, "scale": 1.0},
}


def staircase(key, n: int, hold: int = 25) -> np.ndarray:
    """A random staircase in [-1, 1] (levels uniform, `hold` samples each)."""
    levels = np.asarray(jr.uniform(key, (n // hold + 1,), minval=-1.0, maxval=1.0))
    return np.repeat(levels, hold)[:n]


def tiny_case(key, effect: str, *, n: int = 400, noise: float = 1e-4) -> tuple:
    """`(plant, dt, estimation, validation)` with `effect` withheld from `plant`.

    `effect` is a deterministic catalogue name or `"none"`; outputs carry white
    noise of std `noise` (drawn from `key`).
    """
    k_est, k_val, k_e1, k_e2 = jr.split(key, 4)
    plant = nominal()
    truth = _Truth(plant, effect, EXACT_PARAMS.get(effect, {}), realistic=False)
    recs = []
    for k_in, k_noise in ((k_est, k_e1), (k_val, k_e2)):
        v = staircase(k_in, n)
        w = truth.output(v, DT)
        y = w + noise * np.asarray(jr.normal(k_noise, (n,)))
        recs.append({"t": np.arange(n) * DT, "v": v, "y": y})
    return plant, DT, recs[0], recs[1]


def coloured_case(key, *, n: int = 400, pole: float = 0.9, std: float = 0.02) -> tuple:
    """Nominal output plus AR(1) noise (no white part): a `coloured_noise` case."""
    cases = tiny_case(key, "none", n=n, noise=0.0)
    for i, rec in enumerate(cases[2:]):
        e = np.asarray(jr.normal(jr.fold_in(key, 100 + i), (n,))) * std
        rec["y"] = rec["y"] + _lfilter(np.array([1.0]), np.array([1.0, -pole]), e)
    return cases


def run_demo(key, out) -> list[tuple[str, str]]:
    """Demo section: diagnose a built-in withheld-saturation case, write its report
    and figures into `out/diagnosis/` (for `hamjax demo`)."""
    from pathlib import Path

    from ...diagnosis.diagnose import diagnose_gap
    from ...diagnosis.report import write_diagnosis
    from ...plotting.diagnosis import save_diagnosis_figures

    folder = Path(out) / "diagnosis"
    d = diagnose_gap(*tiny_case(key, "saturation", n=600, noise=0.01))
    name = "built-in withheld saturation"
    write_diagnosis(d, folder, name, nominal="the built-in nominal (model given)")
    save_diagnosis_figures(d, folder, name)
    return [
        (str(folder / "report.md"), f"diagnosis report: named {d.effect}"),
        (str(folder / "validation.png"), "nominal vs augmented vs measured"),
        (str(folder / "ranking.png"), "candidate ranking"),
        (str(folder / "residual_amplitude.png"), "residual vs amplitude/direction"),
        (str(folder / "residual_spectrum.png"), "residual spectrum vs noise floor"),
    ]
