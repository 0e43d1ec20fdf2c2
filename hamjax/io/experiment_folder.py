"""Experiment folders (`docs/experiment-folder.md`): the design and the measured data."""

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .._errors import UserInputError
from .csv import read_csv, sampling_period
from .files import read_json


def read_design(folder: Path, method: str, required: Sequence[str] = ()) -> dict:
    """experiment.json of `folder`, checked to be a `method` design holding `required`."""
    path = Path(folder) / "experiment.json"
    if not path.is_file():
        raise UserInputError(
            f"{path}: file not found (run `hamjax experiment {method}`)"
        )
    design = read_json(path)
    if design.get("method") != method:
        raise UserInputError(
            f"{path}: method is {design.get('method')!r}, not {method!r}"
        )
    for key in required:
        if key not in design:
            raise UserInputError(f"{path}: missing key {key!r}")
    if "dt" in design:
        _positive_number(path, "dt", design["dt"])
    return design


def _positive_number(path: Path, key: str, x) -> float:
    """`x` as a positive finite float, or a `UserInputError` naming `path` and `key`."""
    ok = isinstance(x, int | float) and not isinstance(x, bool)
    try:
        f = float(x) if ok else float("nan")
    except OverflowError:
        f = float("inf")
    if not (np.isfinite(f) and f > 0):
        raise UserInputError(
            f"{path}: {key!r} must be a positive number; got {x!r:.60}"
        )
    return f


def read_data(folder: Path, design: dict, v_designed: np.ndarray) -> np.ndarray:
    """y of data.csv after checking it against the design: row count, t starting at 0
    with step dt, and v equal to the designed input (the contract: never trusted
    blindly)."""
    path = Path(folder) / "data.csv"
    data = read_csv(path, required=("t", "v", "y"))
    n = v_designed.shape[0]
    dt = _positive_number(Path(folder) / "experiment.json", "dt", design.get("dt"))
    t, v = data["t"], data["v"]
    if t.shape[0] != n:
        raise UserInputError(
            f"{path}: {t.shape[0]} rows but experiment.json designs {n} samples"
        )
    step = sampling_period(t)
    if abs(t[0]) > 1e-9 * dt or abs(step - dt) > 1e-6 * dt:
        raise UserInputError(
            f"{path}: t must start at 0 with step dt = {dt:g} (experiment.json); "
            f"got t0 = {t[0]:g}, step {step:g}"
        )
    bad = np.abs(v - v_designed) > 1e-9 * (1.0 + np.max(np.abs(v_designed)))
    if bad.any():
        i = int(np.argmax(bad))
        raise UserInputError(
            f"{path}: column v differs from the designed input at line {i + 2} "
            f"(t = {t[i]:g}): {v[i]:g} vs {v_designed[i]:g}"
        )
    return data["y"]
