"""Atomic writes and JSON reading with errors that name the file."""

import json
import os
import secrets
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import UserInputError


def _temporary_beside(path: Path) -> tuple[int, Path]:
    """Create a new empty file beside `path` for writing; mode 0o666 less the
    umask, as `open()` makes it (`tempfile.mkstemp` would make it 0o600)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    while True:
        tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write `text` to `path` through a temporary file and a rename; the file gets
    the permissions the user's umask gives a new file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _temporary_beside(path)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _to_jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "__array__") and not isinstance(obj, str | bytes):
        arr = np.asarray(obj)
        return _to_jsonable(arr.tolist()) if arr.ndim else _to_jsonable(arr.item())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None  # JSON has no NaN/inf; null is the portable spelling
    if isinstance(obj, np.generic):
        return _to_jsonable(obj.item())
    return obj


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write `obj` (arrays allowed; NaN/inf become null) as indented JSON, atomically."""
    atomic_write_text(path, json.dumps(_to_jsonable(obj), indent=2) + "\n")


def read_text(path: Path) -> str:
    """The text of `path` decoded as UTF-8 (a leading byte-order mark dropped).

    **Raises:** `UserInputError` naming the file if it is missing or not UTF-8.
    """
    if not path.is_file():
        what = "is a folder, not a file" if path.is_dir() else "file not found"
        raise UserInputError(f"{path}: {what}")
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise UserInputError(f"{path}: cannot be read ({err.strerror})") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise UserInputError(
            f"{path}: not UTF-8 text (byte 0x{raw[err.start]:02x} at offset {err.start})"
        ) from None


def read_json(path: str | os.PathLike) -> dict:
    """Read a JSON object; `UserInputError` naming the file if missing or malformed."""
    path = Path(path)
    text = read_text(path)
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as err:
        raise UserInputError(
            f"{path}: not valid JSON ({err.msg}, line {err.lineno})"
        ) from None
    except RecursionError:
        raise UserInputError(f"{path}: JSON nested too deeply") from None
    if not isinstance(obj, dict):
        raise UserInputError(f"{path}: expected a JSON object at the top level")
    return obj
