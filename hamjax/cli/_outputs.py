"""Output safety of the subcommands, checked before any computation: an --out that
cannot be written, that is a file where a folder is meant (or the reverse), or
that already holds the results of an earlier run is refused in one line."""

import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from .._errors import UserInputError


# What `hamjax diagnose` writes into a case's output folder (`report.write_diagnosis`,
# `plotting.diagnosis.save_diagnosis_figures`) and `hamjax blind score` beside them.
DIAGNOSIS_OUTPUTS = (
    "diagnosis.json",
    "report.md",
    "nominal_model.json",
    "residual_amplitude.png",
    "residual_spectrum.png",
    "validation.png",
    "ranking.png",
)
# What `hamjax blind score` writes into RESULTS.
SCORE_OUTPUTS = ("score.json", "reliability.png")
# What `hamjax blind make` writes: DIR/truth.json and DIR/cases/<case>/ holding these.
BLIND_CASE_FILES = ("model.json", "estimation.csv", "validation.csv")


def _nearest_existing(path: Path) -> Path:
    """`path` or its closest ancestor that exists (`.` for a relative path)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _check_creatable(path: Path, option: str) -> None:
    """`path` (file or folder) can be made or replaced: the nearest existing
    ancestor of its parent is a writable folder."""
    base = _nearest_existing(path.parent)
    if not base.is_dir():
        raise UserInputError(
            f"{path}: {option} cannot be created ({base} is a file, not a folder)"
        )
    if not os.access(base, os.W_OK | os.X_OK):
        raise UserInputError(f"{path}: {option} is not writable ({base} is read-only)")


def check_output_file(path: Path, option: str = "--out") -> None:
    """Refuse an output file that is a folder or cannot be written."""
    path = Path(path)
    if path.is_dir():
        raise UserInputError(
            f"{path}: {option} is a folder; give a file name (e.g. {path / 'data.csv'})"
        )
    if path.exists() and not os.access(path, os.W_OK):
        raise UserInputError(f"{path}: {option} is not writable")
    _check_creatable(path, option)


def check_output_folder(path: Path, option: str = "--out") -> None:
    """Refuse an output folder that is an existing file or cannot be written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserInputError(f"{path}: {option} is an existing file, not a folder")
    _check_creatable(path / "x", option)


def earlier_diagnosis(out: Path) -> list[Path]:
    """The files an earlier `hamjax diagnose` (or `blind score`) left in `out`: its
    own output files and those of its per-case subfolders, nothing else."""
    out = Path(out)
    if not out.is_dir():
        return []
    found = [
        out / n for n in (*DIAGNOSIS_OUTPUTS, *SCORE_OUTPUTS) if (out / n).is_file()
    ]
    for sub in sorted(p for p in out.iterdir() if p.is_dir()):
        found += [sub / n for n in DIAGNOSIS_OUTPUTS if (sub / n).is_file()]
    return found


def earlier_blind(out: Path) -> list[Path]:
    """The files an earlier `hamjax blind make` left in `out`."""
    out = Path(out)
    found = [out / "truth.json"] if (out / "truth.json").is_file() else []
    cases = out / "cases"
    if cases.is_dir():
        for sub in sorted(p for p in cases.iterdir() if p.is_dir()):
            found += [sub / n for n in BLIND_CASE_FILES if (sub / n).is_file()]
    return found


def is_nonempty_folder(path: Path) -> bool:
    """Whether `path` is a folder with anything in it."""
    return Path(path).is_dir() and any(Path(path).iterdir())


def refuse_unless_forced(out: Path, earlier: Sequence[Path], force: bool, what: str):
    """One-line refusal to write into `out` over `earlier` results without --force."""
    if earlier and not force:
        first = earlier[0].relative_to(out)
        more = f" and {len(earlier) - 1} more" if len(earlier) > 1 else ""
        raise UserInputError(
            f"{out}: already holds {what} ({first}{more}); add --force to replace "
            "them, or choose another --out"
        )


def remove_files(files: Iterable[Path], root: Path) -> int:
    """Remove `files`, then the folders under `root` that this left empty."""
    n, folders = 0, set()
    for f in files:
        f.unlink(missing_ok=True)
        n += 1
        folders.update(p for p in f.parents if root in p.parents)
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    return n


def unique_names(folders: Sequence[Path], out: Path) -> tuple[list[str], list[str]]:
    """Output subfolder names of the case folders, in order: each folder's own name,
    with `-2`, `-3`, ... added to a name already taken. Also the notes saying so."""
    names: list[str] = []
    notes: list[str] = []
    taken: set[str] = set()
    base = [Path(f).resolve().name for f in folders]
    for folder, name in zip(folders, base, strict=True):
        unique, k = name, 1
        while unique in taken:
            k += 1
            unique = f"{name}-{k}"
        if unique != name:
            notes.append(
                f"{base.count(name)} cases are named {name}: {folder} is written to "
                f"{Path(out) / unique}"
            )
        taken.add(unique)
        names.append(unique)
    return names, notes


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one existing file."""
    try:
        return Path(a).exists() and Path(b).exists() and Path(a).samefile(b)
    except OSError:
        return False
