"""Read a gap case folder (`estimation.csv`, `validation.csv`, optional `model.json`)."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._errors import UserInputError
from ..io import load_model, read_csv, require_stable, sampling_period
from ..models import Hammerstein


MIN_SAMPLES = 50
# The batched fits hold every candidate row's copy of the records: peak memory grows
# by about 3 KB per sample (2 million samples per record took 6.3 GB), so longer
# records are refused before any work; decimate them first (an anti-aliasing
# `scipy.signal.decimate`), which also suits the diagnosis's low-order models.
MAX_SAMPLES = 500_000


@dataclass(frozen=True)
class GapCase:
    """A case: two records of the same plant and, optionally, its nominal model."""

    name: str
    folder: Path
    estimation: dict  # {"t", "v", "y"} float arrays
    validation: dict
    dt: float
    model: Hammerstein | None
    model_dt: float | None


def _check_record(path: Path, rec: dict) -> float:
    n = rec["t"].shape[0]
    if n < MIN_SAMPLES:
        raise UserInputError(f"{path}: only {n} samples (need at least {MIN_SAMPLES})")
    if n > MAX_SAMPLES:
        raise UserInputError(
            f"{path}: {n} samples, more than the {MAX_SAMPLES} a diagnosis holds in "
            f"memory (about 3 KB per sample): decimate the record first, e.g. "
            f"scipy.signal.decimate(x, {int(np.ceil(n / MAX_SAMPLES))})"
        )
    if np.ptp(rec["v"]) == 0:
        raise UserInputError(f"{path}: input v is constant (nothing to identify)")
    if np.ptp(rec["y"]) == 0:
        raise UserInputError(f"{path}: output y is constant (a dead sensor?)")
    return sampling_period(rec["t"])  # the mean step: float32 timestamps too


def read_case(folder: str | Path) -> GapCase:
    """Read and check a case folder.

    **Raises:** `UserInputError` naming the file and the problem (missing or
    malformed CSV, NaN/inf, non-uniform `t`, different `dt` in the two records,
    constant input or output, unknown model kind, an unstable model, a model `dt` that
    differs from the data).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise UserInputError(f"{folder}: not a case folder (directory not found)")
    est_path, val_path = folder / "estimation.csv", folder / "validation.csv"
    est = read_csv(est_path, ("t", "v", "y"))
    val = read_csv(val_path, ("t", "v", "y"))
    dt_e, dt_v = _check_record(est_path, est), _check_record(val_path, val)
    if not np.isclose(dt_e, dt_v, rtol=1e-6, atol=0.0):
        raise UserInputError(
            f"{val_path}: sampling period {dt_v:.6g} s differs from estimation.csv's "
            f"{dt_e:.6g} s"
        )
    model, model_dt = None, None
    model_path = folder / "model.json"
    if model_path.exists():
        model, model_dt = load_model(model_path)
        require_stable(model, model_path, integrating=True)
        if model_dt is not None and not np.isclose(model_dt, dt_e, rtol=1e-6):
            raise UserInputError(
                f"{model_path}: discrete model dt {model_dt:.6g} s differs from the data's "
                f"{dt_e:.6g} s"
            )
    return GapCase(folder.resolve().name, folder, est, val, dt_e, model, model_dt)
