"""Diagnose the measured datasets of `../shared/data/real/` (adapters in
`hamjax.diagnosis.real_data`) and tabulate the effect named against the literature."""

import time
from pathlib import Path

from ....montecarlo.registry import StudyOption, option_values


NAME = "real-data-gap"
DESCRIPTION = (
    "diagnosis of the real datasets (effect named, gap before/after vs literature)"
)
DEFAULT_REALISATIONS = 80  # stiction loops included
DEFAULT_CHUNK = 4  # cases per batch (`diagnosis.schedule.CASES_PER_BATCH`)
SPLIT_CPU = True  # `hamjax study` exposes each core as a device first


# ../shared beside the clone: hamjax/papers/gap/studies/ is four folders down.
OPTIONS = (
    StudyOption(
        "data",
        Path(__file__).resolve().parents[5] / "shared" / "data" / "real",
        "folder of the real datasets (default ../shared/data/real)",
        Path,
    ),
)


def run(key, *, realisations, chunk, out, quiet, args) -> dict:
    from ....diagnosis.case import read_case
    from ....diagnosis.diagnose import diagnose_many
    from ....diagnosis.nominal_fit import fit_nominal
    from ....diagnosis.real_data import write_real_cases
    from ....diagnosis.report import write_diagnosis
    from ....io import atomic_write_text, model_to_dict, write_json

    del key  # deterministic
    out = Path(out)
    data = option_values(args, OPTIONS).data
    notes = write_real_cases(data, out / "cases", stiction_loops=realisations)
    names = sorted(notes)
    start = time.perf_counter()
    items, kept, skipped = [], [], {}
    for n in names:
        try:  # a record the diagnosis refuses is reported, not fatal
            c = read_case(out / "cases" / n)
            plant = fit_nominal(c.dt, c.estimation)
        except ValueError as err:
            skipped[n] = str(err)
            continue
        write_json(
            out / "results" / n / "nominal_model.json", model_to_dict(plant, c.dt)
        )
        items.append((plant, c.dt, c.estimation, c.validation))
        kept.append(n)
    res = diagnose_many(items, cases_per_batch=chunk)
    rows = [
        "| case | effect named | gap before | gap after | noise floor | literature |",
        "|---|---|---|---|---|---|",
    ]
    table = {}
    for n, d in zip(kept, res, strict=False):
        write_diagnosis(d, out / "results" / n, n)
        table[n] = {
            "effect": d.effect,
            "gap_before": d.gap_before,
            "gap_after": d.gap_after,
            "noise_floor": d.noise_floor,
            "literature": notes[n],
        }
        rows.append(
            f"| {n} | {d.effect} | {d.gap_before:.4g} | {d.gap_after:.4g} | "
            f"{d.noise_floor:.4g} | {notes[n]} |"
        )
    for n, why in skipped.items():
        rows.append(
            f"| {n} | not diagnosed: {why.split(': ', 1)[-1]} | | | | {notes[n]} |"
        )
    atomic_write_text(out / "table.md", "\n".join(rows) + "\n")
    summary = {
        "cases": table,
        "skipped": skipped,
        "seconds": time.perf_counter() - start,
    }
    write_json(out / "summary.json", summary)
    if not quiet:
        print("\n".join(rows))
    return summary
