"""Signal CSV files (`t,v` and `t,v,y`): strict reading and atomic writing."""

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .._errors import UserInputError
from .files import atomic_write_text


def read_csv(
    path: str | os.PathLike,
    required: Sequence[str] = ("t", "v", "y"),
    *,
    uniform: bool = True,
    rtol: float = 1e-6,
) -> dict[str, np.ndarray]:
    """Read a signal CSV with a header row.

    Checks: the file exists and parses; every `required` column is present (extra
    columns are kept and ignored by callers); at least two rows; every value of a
    required column is finite; `t` (if required) is uniformly sampled within
    `rtol` of its step, strictly increasing.

    **Returns:** `{column: float64 array}`.

    **Raises:** `UserInputError` naming the file and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: file not found")
    text = path.read_text()
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise UserInputError(f"{path}: empty file")
    header = [h.strip() for h in lines[0].split(",")]
    missing = [c for c in required if c not in header]
    if missing:
        raise UserInputError(
            f"{path}: missing column(s) {', '.join(missing)} (header is "
            f"{','.join(header)}; expected {','.join(required)})"
        )
    try:
        data = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2)
    except ValueError as err:
        raise UserInputError(f"{path}: malformed numbers ({err})") from None
    if data.shape[0] < 2:
        raise UserInputError(
            f"{path}: needs at least 2 rows of data; got {data.shape[0]}"
        )
    if data.shape[1] != len(header):
        raise UserInputError(
            f"{path}: {data.shape[1]} values per row but {len(header)} header names"
        )
    cols = {name: data[:, i].astype(float) for i, name in enumerate(header)}
    for name in required:
        bad = ~np.isfinite(cols[name])
        if bad.any():
            row = int(np.argmax(bad)) + 2
            kind = "NaN" if np.isnan(cols[name][bad][0]) else "inf"
            raise UserInputError(f"{path}: column {name} has {kind} (line {row})")
    if uniform and "t" in required:
        t = cols["t"]
        steps = np.diff(t)
        dt = steps[0]
        if not dt > 0:
            raise UserInputError(f"{path}: t must be strictly increasing")
        if np.any(np.abs(steps - dt) > rtol * abs(dt)):
            i = int(np.argmax(np.abs(steps - dt) > rtol * abs(dt)))
            raise UserInputError(
                f"{path}: t is not uniformly sampled (step {steps[i]:g} at line {i + 3}, "
                f"first step {dt:g})"
            )
    return cols


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray]) -> None:
    """Write equal-length columns with a header row, full precision, atomically."""
    names = list(columns)
    arrays = [np.asarray(columns[n], dtype=float).ravel() for n in names]
    if len({a.shape[0] for a in arrays}) != 1:
        raise ValueError(f"columns {names} have different lengths")
    buf = io.StringIO()
    np.savetxt(
        buf,
        np.column_stack(arrays),
        delimiter=",",
        fmt="%.17g",
        header=",".join(names),
        comments="",
    )
    atomic_write_text(path, buf.getvalue())


def sampling_period(t: np.ndarray) -> float:
    """The sampling period of a uniform time vector (mean step, robust to round-off)."""
    return float((t[-1] - t[0]) / (t.shape[0] - 1))
