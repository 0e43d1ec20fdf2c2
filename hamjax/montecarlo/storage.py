"""The output folder of a Monte Carlo run: manifest, atomic chunk files, resume.

Layout of `out/`:

- `manifest.json`: what was run (study name, seed/key and the key's PRNG
  implementation, R, C, the study's configuration, output shapes) and the package
  versions (and the device and process counts, informational);
- `chunks/chunk_<start>-<stop>.npz`: the per-realisation outputs of
  realisations `start <= r < stop`, one array `leaf_<i>` per output leaf.

Each file is written to a temporary name in the same folder and renamed
(`os.replace` is atomic on POSIX and Windows), so a killed run leaves only
complete files (plus, at worst, a stale temporary that is removed on resume).
"""

import contextlib
import datetime
import io
import json
import os
import platform
import re
import tempfile
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import numpy as np


FORMAT = "hamjax.montecarlo/1"
MANIFEST = "manifest.json"
CHUNKS = "chunks"
# Entries that must agree for a folder to be resumed; the rest is informational.
_CHECKED = (
    "format",
    "study",
    "seed",
    "key",
    "key_impl",
    "realisations",
    "chunk",
    "outputs",
    "config",
)
_CHUNK_NAME = re.compile(r"^chunk_(\d+)-(\d+)\.npz$")
_PACKAGES = ("hamjax", "jax", "jaxlib", "equinox", "numpy")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` via a temporary file and `os.replace`."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def jsonable(obj: Any) -> Any:
    """`obj` as it reads back from JSON (paths and other objects become strings)."""
    return json.loads(json.dumps(obj, default=str, sort_keys=True))


def package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def make_manifest(
    *,
    study: str,
    seed: int | None,
    key_data: list,
    key_impl: str,
    realisations: int,
    chunk: int,
    outputs: list[dict],
    config: dict,
    n_devices: int,
    n_processes: int = 1,
) -> dict:
    manifest = {
        "format": FORMAT,
        "study": study,
        "seed": seed,
        "key": key_data,
        "key_impl": key_impl,
        "realisations": realisations,
        "chunk": chunk,
        "outputs": outputs,
        "config": config,
        "devices": n_devices,
        "processes": n_processes,
        "versions": package_versions(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    return jsonable(manifest)


def open_folder(out: Path, manifest: dict) -> list[tuple[int, int]]:
    """Create `out` with `manifest`, or check an existing one; return finished ranges.

    **Raises:** `ValueError` if `out` holds a manifest of a different run, or chunk
    files that do not fit it.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"output folder {out} exists and is not a folder")
    (out / CHUNKS).mkdir(parents=True, exist_ok=True)
    path = out / MANIFEST
    if path.exists():
        try:
            existing = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"file {path}: unreadable manifest ({err})") from None
        mismatched = [k for k in _CHECKED if existing.get(k) != manifest.get(k)]
        if mismatched:
            details = "; ".join(
                f"{k}: folder has {_short(existing.get(k))}, this run has "
                f"{_short(manifest.get(k))}"
                for k in mismatched
            )
            raise ValueError(
                f"output folder {out} holds a different Monte Carlo run ({details}); "
                "use another --out folder, or delete this one to start again"
            )
    else:
        atomic_write_bytes(path, (json.dumps(manifest, indent=2) + "\n").encode())
    _remove_stale_temporaries(out / CHUNKS)
    return finished_ranges(out, manifest["realisations"])


def finished_ranges(out: Path, realisations: int) -> list[tuple[int, int]]:
    """Sorted `(start, stop)` of the chunk files in `out`, checked for overlaps."""
    ranges = []
    for p in (Path(out) / CHUNKS).iterdir():
        m = _CHUNK_NAME.match(p.name)
        if m is None:
            continue
        start, stop = int(m.group(1)), int(m.group(2))
        if not 0 <= start < stop <= realisations:
            raise ValueError(
                f"file {p}: realisations {start}..{stop} outside 0..{realisations}"
            )
        ranges.append((start, stop))
    ranges.sort()
    for (a0, a1), (b0, b1) in zip(ranges, ranges[1:], strict=False):
        if b0 < a1:
            raise ValueError(
                f"folder {Path(out) / CHUNKS}: chunks {a0}-{a1} and {b0}-{b1} overlap"
            )
    return ranges


def chunk_path(out: Path, start: int, stop: int) -> Path:
    return Path(out) / CHUNKS / f"chunk_{start:010d}-{stop:010d}.npz"


def write_chunk(out: Path, start: int, stop: int, leaves: list[np.ndarray]) -> None:
    """Atomically write the outputs of realisations `start <= r < stop`."""
    buffer = io.BytesIO()
    np.savez(buffer, **{f"leaf_{i}": leaf for i, leaf in enumerate(leaves)})
    atomic_write_bytes(chunk_path(out, start, stop), buffer.getvalue())


def read_chunk(
    out: Path, start: int, stop: int, outputs: list[dict]
) -> list[np.ndarray]:
    """Read a chunk file and check it against the expected `outputs` spec."""
    path = chunk_path(out, start, stop)
    try:
        with np.load(path, allow_pickle=False) as data:
            leaves = [data[f"leaf_{i}"] for i in range(len(outputs))]
    except (OSError, KeyError, ValueError) as err:
        raise ValueError(f"file {path}: unreadable chunk ({err})") from None
    for leaf, spec in zip(leaves, outputs, strict=True):
        expected = (stop - start, *spec["shape"])
        if leaf.shape != expected or str(leaf.dtype) != spec["dtype"]:
            raise ValueError(
                f"file {path}: output {spec['name']} has shape {leaf.shape} and dtype "
                f"{leaf.dtype}; expected {expected} and {spec['dtype']}"
            )
    return leaves


def _remove_stale_temporaries(folder: Path) -> None:
    for p in folder.glob(".*.tmp"):
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 80 else text[:77] + "..."
