"""Blind withheld-effect benchmark: accuracy, false alarm on `none`, shrink and speed
of `hamjax diagnose` on cases drawn by `hamjax blind make` (exact and realistic)."""

import time
from pathlib import Path

import jax.random as jr

from ...._argtypes import word_list
from ....montecarlo.registry import StudyOption, option_values


NAME = "blind-benchmark"
DESCRIPTION = (
    "diagnosis of withheld-effect cases (exact + realistic): confusion, accuracy, "
    "false alarm on none, median shrink, seconds per case"
)
DEFAULT_REALISATIONS = 240
DEFAULT_CHUNK = 4  # cases per batch (`diagnosis.schedule.CASES_PER_BATCH`)
SPLIT_CPU = True  # `hamjax study` exposes each core as a device first
DIAGNOSES = True  # and caps XLA's ISA (`_runtime.same_rounding_in_every_lane`)


OPTIONS = (
    StudyOption(
        "modes", ["exact", "realistic"], "comma-separated realism modes", word_list
    ),
)


def run(key, *, realisations, chunk, out, quiet, args) -> dict:
    import matplotlib.pyplot as plt

    from ....diagnosis.case import read_case
    from ....diagnosis.diagnose import diagnose_many
    from ....io import write_json
    from ....plotting.diagnosis import plot_confusion
    from ..blind import format_score, make_cases, score

    out = Path(out)
    modes = option_values(args, OPTIONS).modes
    summary = {}
    for i, mode in enumerate(modes):
        folder = out / mode
        truth = make_cases(jr.fold_in(key, i), realisations, folder, realism=mode)
        names = sorted(truth["cases"])
        cases = [read_case(folder / "cases" / n) for n in names]
        start = time.perf_counter()
        res = diagnose_many(
            [(c.model, c.dt, c.estimation, c.validation) for c in cases],
            cases_per_batch=chunk,
        )
        seconds = time.perf_counter() - start
        named = {n: r.effect for n, r in zip(names, res, strict=False)}
        gaps = {
            n: (r.gap_before, r.gap_after) for n, r in zip(names, res, strict=False)
        }
        s = score(truth, named, gaps)
        s["seconds_total_incl_compile"] = seconds
        s["seconds_per_case"] = seconds / len(names)
        summary[mode] = s
        if not quiet:
            print(f"[{mode}]\n{format_score(s)}\n{seconds / len(names):.2f} s per case")
        fig = plot_confusion(s)
        fig.tight_layout()
        fig.savefig(out / f"confusion_{mode}.png", dpi=110)
        plt.close(fig)
    write_json(out / "summary.json", summary)
    return summary
