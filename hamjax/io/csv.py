"""Signal CSV files (`t,v` and `t,v,y`): strict reading and atomic writing.

The reader accepts what spreadsheets, R and pandas write (see `read_csv`); the
format is described in `docs/gap-case-folder.md` and `docs/experiment-folder.md`.
"""

import csv
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .._errors import UserInputError
from .files import atomic_write_text, read_text


# Timestamps written in single precision carry about 7 significant digits: a step
# read from them is off by up to one float32 ulp of the largest |t|.
FLOAT32_EPS = float(np.finfo(np.float32).eps)


def _fields(path: Path, lineno: int, line: str) -> list[str]:
    """The comma-separated fields of one line, quotes removed, blanks stripped."""
    try:
        row = next(csv.reader([line], strict=True), [])
    except csv.Error as err:
        raise UserInputError(
            f"{path}: line {lineno}: malformed quoting ({err})"
        ) from None
    return [f.strip().lstrip("\ufeff") for f in row]


def _content_lines(text: str) -> tuple[list[str], list[int]]:
    """The non-blank lines that are not `#` comments, and their 1-based numbers."""
    lines, numbers = [], []
    for i, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            lines.append(line)
            numbers.append(i)
    return lines, numbers


def _split(text: str) -> tuple[tuple[int, str] | None, list[str], list[int]]:
    """`(header, rows, numbers)`: the first content line (`_content_lines`) with
    its number (None: no content line), the data rows after it and their numbers."""
    lines, numbers = _content_lines(text)
    if not lines:
        return None, [], []
    return (numbers[0], lines[0]), lines[1:], numbers[1:]


def count_rows(path: str | os.PathLike) -> int:
    """The number of data rows `read_csv(path)` reads (the content lines after the
    header: blank and `#` comment lines skipped), without parsing them.

    **Raises:** `UserInputError` if the file does not read (`files.read_text`)."""
    return len(_split(read_text(Path(path)))[1])


def _header(path: Path, lineno: int, line: str) -> list[str]:
    """Column names of the header line: unnamed columns (R's or pandas' row index)
    are `""`; a repeated name is refused."""
    names = _fields(path, lineno, line)
    seen = set()
    for name in names:
        if name and name in seen:
            raise UserInputError(
                f"{path}: column name {name} appears twice in the header (line {lineno})"
            )
        seen.add(name)
    return names


def _table_slow(
    path: Path, rows: list[str], numbers: list[int], header: list[str], keep: list[int]
) -> np.ndarray:
    """Parse row by row; the first bad line is named. Used when the fast parse fails."""
    out = np.empty((len(rows), len(keep)))
    for r, (lineno, line) in enumerate(zip(numbers, rows, strict=True)):
        fields = _fields(path, lineno, line)
        if len(fields) != len(header):
            raise UserInputError(
                f"{path}: line {lineno} has {len(fields)} values but the header has "
                f"{len(header)} names"
            )
        for c, i in enumerate(keep):
            try:
                out[r, c] = float(fields[i])
            except ValueError:
                raise UserInputError(
                    f"{path}: line {lineno}: malformed number {fields[i]!r} in column "
                    f"{header[i]}"
                ) from None
    return out


def _table(
    path: Path, rows: list[str], numbers: list[int], header: list[str], keep: list[int]
) -> np.ndarray:
    """The named columns as floats, shape `(rows, len(keep))`."""
    if all(line.count(",") == len(header) - 1 for line in rows):
        try:
            return np.loadtxt(
                rows,
                delimiter=",",
                quotechar='"',
                comments=None,
                usecols=keep,
                ndmin=2,
                dtype=float,
            )
        except ValueError:
            pass  # the slow parse names the line
    return _table_slow(path, rows, numbers, header, keep)


def _check_uniform(path: Path, t: np.ndarray, numbers: list[int], rtol: float) -> None:
    """`t` strictly increasing and uniformly sampled (tolerance: see `read_csv`)."""
    steps = np.diff(t)
    if not np.all(steps > 0):
        i = int(np.argmax(~(steps > 0)))
        raise UserInputError(
            f"{path}: t must be strictly increasing (line {numbers[i + 1]})"
        )
    dt = (t[-1] - t[0]) / (t.shape[0] - 1)
    tol = rtol * dt + 2 * FLOAT32_EPS * float(np.max(np.abs(t)))
    off = np.abs(steps - dt) > tol
    if off.any():
        i = int(np.argmax(off))
        raise UserInputError(
            f"{path}: t is not uniformly sampled (step {steps[i]:g} at line "
            f"{numbers[i + 1]}, mean step {dt:g})"
        )


def read_csv(
    path: str | os.PathLike,
    required: Sequence[str] = ("t", "v", "y"),
    *,
    uniform: bool = True,
    rtol: float = 1e-6,
) -> dict[str, np.ndarray]:
    """Read a signal CSV with a header row.

    Accepted: UTF-8 with or without a byte-order mark (Excel's "CSV UTF-8");
    `#` comment lines and blank lines anywhere (skipped); quoted names and
    values (R's `write.csv`); unnamed columns, e.g. the row index R or pandas
    write first (ignored); CRLF line ends. The delimiter is a comma.

    Checks: the file exists and parses; every `required` column is present (extra
    columns are kept and ignored by callers); at least two rows; every value of a
    required column is finite; `t` (if required) strictly increasing and uniformly
    sampled: every step within `rtol * dt + 2 * eps32 * max|t|` of the mean step
    `dt`, where `eps32` = 1.19e-7 is the float32 epsilon. The second term is the
    rounding of timestamps stored in single precision (one float32 ulp of the
    largest |t| on each of two timestamps); for float64 timestamps it is far
    below any real sampling jitter.

    **Returns:** `{column: float64 array}` (unnamed columns are left out).

    **Raises:** `UserInputError` naming the file, and the line where there is one.
    """
    path = Path(path)
    first, rows, numbers = _split(read_text(path))
    if first is None:
        raise UserInputError(f"{path}: empty file (no header line)")
    header = _header(path, *first)
    missing = [c for c in required if c not in header]
    if missing:
        hint = (
            "; the delimiter must be a comma"
            if len(header) == 1 and any(s in first[1] for s in ";\t")
            else ""
        )
        raise UserInputError(
            f"{path}: missing column(s) {', '.join(missing)} (header is "
            f"{','.join(header)}; expected {','.join(required)}{hint})"
        )
    if len(rows) < 2:
        raise UserInputError(f"{path}: needs at least 2 rows of data; got {len(rows)}")
    keep = [i for i, name in enumerate(header) if name]
    data = _table(path, rows, numbers, header, keep)
    cols = {header[i]: data[:, c].astype(float) for c, i in enumerate(keep)}
    for name in required:
        bad = ~np.isfinite(cols[name])
        if bad.any():
            k = int(np.argmax(bad))
            kind = "NaN" if np.isnan(cols[name][k]) else "inf"
            raise UserInputError(
                f"{path}: column {name} has {kind} (line {numbers[k]})"
            )
    if uniform and "t" in required:
        _check_uniform(path, cols["t"], numbers, rtol)
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
