"""Writing gap-case folders (the contract `shared/contracts/gap-case.md`, described
in `docs/gap-case-folder.md`); `hamjax.diagnosis.case` reads them."""

from pathlib import Path

from .csv import write_csv
from .files import write_json


def write_case(out: Path, i: int, case: dict) -> str:
    """Write case `i` of a blind set, a dict with `model` (model.json), `estimation`
    and `validation` (columns t, v, y), as `out/cases/case_NNNN`; returns the name."""
    name = f"case_{i:04d}"
    folder = Path(out) / "cases" / name
    write_json(folder / "model.json", case["model"])
    write_csv(folder / "estimation.csv", case["estimation"])
    write_csv(folder / "validation.csv", case["validation"])
    return name
