"""Diagnose the measured datasets of `../shared/data/real/` (adapters in
`hamjax.papers.gap.real_data`) and tabulate the effect named against the literature."""

import time
from pathlib import Path

from ...._errors import UserInputError
from ....diagnosis.probabilities import STICTION_LIKE
from ....montecarlo.registry import StudyOption, option_values


NAME = "real-data-gap"
DESCRIPTION = (
    "diagnosis of the real datasets (effect named, gap before/after vs literature)"
)
DEFAULT_REALISATIONS = 80  # stiction loops included
DEFAULT_CHUNK = 4  # cases per batch (`diagnosis.schedule.CASES_PER_BATCH`)
SPLIT_CPU = True  # `hamjax study` exposes each core as a device first
DIAGNOSES = True  # and caps XLA's ISA (`_runtime.same_rounding_in_every_lane`)
# Published best simulation RMSE on the same split (the literature column only:
# nothing in the diagnosis reads it).
PUBLISHED_RMSE = {
    "cascaded_tanks": (0.191, "V", "grey box, Champneys et al. 2024"),
}


# ../shared beside the clone: hamjax/papers/gap/studies/ is four folders down.
OPTIONS = (
    StudyOption(
        "data",
        Path(__file__).resolve().parents[5] / "shared" / "data" / "real",
        "folder of the real datasets (default ../shared/data/real)",
        Path,
    ),
    StudyOption(
        "cases",
        "",
        "comma-separated case names to diagnose (e.g. ced_prbs,cascaded_tanks; "
        "default: every adapted case)",
    ),
)


def select_cases(names: list[str], spec: str) -> list[str]:
    """The case names of `spec` (comma-separated; empty: all `names`), in the order
    of `names`; `ValueError` for a name that is not a case."""
    wanted = [w.strip() for w in spec.split(",") if w.strip()]
    unknown = sorted(set(wanted) - set(names))
    if unknown:
        raise ValueError(f"no such case: {', '.join(unknown)} (have {len(names)})")
    return [n for n in names if not wanted or n in wanted]


def run(key, *, realisations, chunk, out, quiet, args) -> dict:
    from ....diagnosis.case import read_case
    from ....diagnosis.diagnose import diagnose_many
    from ....diagnosis.nominal_fit import fit_nominal_many
    from ....diagnosis.report import where_in_brief, write_diagnosis
    from ....io import atomic_write_text, model_to_dict, write_json
    from ..real_data import write_real_cases

    del key  # deterministic
    out = Path(out)
    opts = option_values(args, OPTIONS)
    notes = write_real_cases(opts.data, out / "cases", stiction_loops=realisations)
    if not notes:  # an empty table is no result
        raise UserInputError(
            f"--data {opts.data}: no real dataset found there (folders such as "
            "cascaded_tanks/, ced_coupled_drives/, emps/, silverbox/): give the "
            "folder ../shared/data/real"
        )
    names = select_cases(sorted(notes), opts.cases)
    start = time.perf_counter()
    read, skipped = {}, {}
    for n in names:
        try:  # a record the diagnosis refuses is reported, not fatal
            read[n] = read_case(out / "cases" / n)
        except ValueError as err:
            skipped[n] = str(err)
    kept = list(read)
    nominals = fit_nominal_many([(c.dt, c.estimation) for c in read.values()])
    items = []
    for n, plant in zip(kept, nominals, strict=True):
        c = read[n]
        write_json(
            out / "results" / n / "nominal_model.json", model_to_dict(plant, c.dt)
        )
        items.append((plant, c.dt, c.estimation, c.validation))
    res = diagnose_many(items, cases_per_batch=chunk, fitted=[True] * len(items))
    rows = [
        "| case | effect named (p) | gap before | gap after | noise floor | "
        "where the gap lies | literature | published best RMSE |",
        "|---|---|---|---|---|---|---|---|",
    ]
    loops = [
        "| loop | effect named (p) | p stiction-like | gap before | gap after |",
        "|---|---|---|---|---|",
    ]
    table = {}
    for n, d in zip(kept, res, strict=False):
        write_diagnosis(d, out / "results" / n, n)
        p = d.probabilities.get(d.effect, 0.0)
        stiction = sum(d.probabilities.get(k, 0.0) for k in STICTION_LIKE)
        where = where_in_brief(d.where)
        published = PUBLISHED_RMSE.get(n)
        table[n] = {
            "effect": d.effect,
            "probability": p,
            "p_stiction_like": stiction,
            "gap_before": d.gap_before,
            "gap_after": d.gap_after,
            "noise_floor": d.noise_floor,
            "where": where,
            "literature": notes[n],
            "published_rmse": None if published is None else list(published),
        }
        if n.startswith("stiction_"):
            loops.append(
                f"| {n.removeprefix('stiction_')} | {d.effect} ({p:.2f}) | "
                f"{stiction:.2f} | {d.gap_before:.4g} | {d.gap_after:.4g} |"
            )
            continue
        pub = (
            ""
            if published is None
            else f"{published[0]} {published[1]} ({published[2]})"
        )
        rows.append(
            f"| {n} | {d.effect} ({p:.2f}) | {d.gap_before:.4g} | {d.gap_after:.4g} | "
            f"{d.noise_floor:.4g} | {where} | {notes[n]} | {pub} |"
        )
    for n, why in skipped.items():
        rows.append(
            f"| {n} | not diagnosed: {why.split(': ', 1)[-1]} | | | | | {notes[n]} | |"
        )
    atomic_write_text(out / "table.md", "\n".join(rows) + "\n")
    if len(loops) > 2:  # what was named per loop; the labels stay withheld
        atomic_write_text(out / "loops.md", "\n".join(loops) + "\n")
    summary = {
        "cases": table,
        "skipped": skipped,
        "seconds": time.perf_counter() - start,
    }
    write_json(out / "summary.json", summary)
    if not quiet:
        print("\n".join(rows))
        if len(loops) > 2:
            print("\n".join(loops))
    return summary
