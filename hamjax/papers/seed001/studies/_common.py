"""What the seed-001 studies share: the `--periods` option, the noise-free record
of a case, the way a study runs its realisations and the way it closes
(`summary.json`)."""

import json
from pathlib import Path

from ...._argtypes import positive_int
from ...._types import Signal
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.storage import atomic_write_bytes
from ....simulation import simulate
from ..._study import run_realisations
from ..plants import RecursivePLCase, pe_input


def periods_option(default: int, help: str) -> StudyOption:
    """`--periods`: how many periods of the input (5.1) a record holds."""
    return StudyOption("periods", default, help, positive_int)


def headless() -> None:
    """Draw without a display (matplotlib's Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")


def clean_record(case: RecursivePLCase, args, options) -> tuple[int, Signal, Signal]:
    """`(periods, v, w)`: the study's `--periods` (one of its `options`), that many
    periods of the input (5.1) for order 2 at `case`'s levels, and `case`'s
    noise-free output."""
    periods = option_values(args, options).periods
    v = pe_input(case.levels, 2, periods)
    return periods, v, simulate(case.plant(), v)


def run_trials(key, trial, name: str, out: Path, args, budget: dict, **metadata):
    """`run_realisations` of `trial` under `name`, written to (and resumed from)
    `out`; `budget` holds the study's `realisations`, `chunk` and `quiet`, and the
    manifest records the study's `--seed` then `metadata`."""
    seed = {"seed": getattr(args, "seed", None)}
    return run_realisations(
        key, trial, name=name, out=out, metadata=seed | metadata, **budget
    )


def write_summary(out: Path, summary: dict) -> dict:
    """Headline the summary with its verdict, write it to `out/summary.json` and
    return it."""
    summary["headline"] = summary["verdict"]
    atomic_write_bytes(
        out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode()
    )
    return summary
