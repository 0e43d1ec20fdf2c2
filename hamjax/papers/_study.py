"""Plumbing shared by the registered studies of every paper."""

from pathlib import Path
from typing import Any

from ..montecarlo.config import MonteCarloConfig
from ..montecarlo.runner import run_monte_carlo


def run_realisations(
    key,
    trial,
    *,
    name: str,
    realisations: int,
    chunk: int,
    out: Path | None,
    quiet: bool,
    metadata: dict[str, Any] | None = None,
):
    """`run_monte_carlo` of a study's `trial`: `realisations` in chunks of `chunk`,
    written to (and resumed from) `out`, with `metadata` in its manifest."""
    config = MonteCarloConfig(realisations=realisations, chunk=chunk, name=name)
    return run_monte_carlo(key, trial, config, out=out, quiet=quiet, metadata=metadata)
