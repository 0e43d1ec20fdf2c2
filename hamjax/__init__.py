"""hamjax: identification of Hammerstein systems with hard input nonlinearities."""

from ._results import RESULTS as RESULTS
from ._x64 import enable_x64 as enable_x64
from .identification import (
    FGIResult as FGIResult,
    NBBIResult as NBBIResult,
    RecursivePLEstimate as RecursivePLEstimate,
    RecursivePLResult as RecursivePLResult,
    identify_fgi as identify_fgi,
    identify_nbbi as identify_nbbi,
    identify_recursive_pl as identify_recursive_pl,
)
from .models import *  # noqa: F403 (the names of `hamjax.models.__all__`)
from .signals import (
    fgi_period_samples as fgi_period_samples,
    initialisation_step as initialisation_step,
    multisine as multisine,
    nbbi_staircase as nbbi_staircase,
    pe_impulse_sequence as pe_impulse_sequence,
    periodic_staircase as periodic_staircase,
    prbs as prbs,
    random_staircase as random_staircase,
)
from .simulation import (
    linear_response as linear_response,
    simulate as simulate,
    simulate_batch as simulate_batch,
    simulate_diffrax as simulate_diffrax,
)


def _version() -> str:
    """The installed distribution's version; from a source tree that is not
    installed, the version in `pyproject.toml` beside the package."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hamjax")
    except PackageNotFoundError:
        pass
    import tomllib
    from pathlib import Path

    try:
        with open(Path(__file__).resolve().parents[1] / "pyproject.toml", "rb") as f:
            return str(tomllib.load(f)["project"]["version"])
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "0+unknown"


__version__ = _version()
