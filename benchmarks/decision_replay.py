"""A change of the decision rule measured on the same fits, in seconds: capture a
set's fits once, then replay the rule of whichever hamjax is first on the path.

    python benchmarks/decision_replay.py capture --set SETS/B9 --out fits/B9.pkl
    python benchmarks/decision_replay.py capture --loops 4 --out fits/L4.pkl
    python benchmarks/decision_replay.py score fits/*.pkl --names before.json
    python benchmarks/decision_replay.py fits fits/*.pkl
    PYTHONPATH=/path/to/worktree python benchmarks/decision_replay.py \\
        score fits/*.pkl --against before.json

`capture` diagnoses a blind set (`hamjax blind make`: `truth.json`, `cases/`;
a case without model.json gets hamjax's own nominal, as in `hamjax diagnose`)
or the seed's control loops (`--loops SEED`: the cases of `hamjax blind make
--family loops --seed SEED`, without model.json) in one `diagnose_many` call,
and pickles per case its truth, its prepared rows and fits (the
`layout.Prepared` and the fit dict that the rule reads) and the name given.
`score` applies the installed hamjax's rule (`--rule`, `diagnose.RULES`) to
those fits and prints per file the accuracy, the false alarms on `none`, and
on control loops the stiction recall and false-alarm rate (names in
`probabilities.STICTION_LIKE`); `--names` writes every case's name,
`--against` reads such a file and lists the cases whose name changed.
`fits` applies no rule: per file, the prediction-error rows that nest the
re-fit yet end above its one-step SSE, the cases with a prediction-error fit
whose linear part leaves the unit circle, and the re-fits that validate worse
than the nominal (docs/diagnosis-history.md, 2026-12-07).

What it can replay: the fits depend only on the fitting code, so a change to
`attribute` or `decide` is measured on the fits captured before it. A change
to the fits, to the candidate rows, or to what the schedule decides while
fitting (which rows are re-fitted by prediction error follows
`attribute.whitening_noise`; the noise candidates are stored with the
fits) needs a new capture. The pickles hold hamjax's internal objects: replay
them with a tree whose `Prepared`, `Row` and `Candidate` are those that
captured them (noise candidates captured before `Candidate.predictor`, 2026-12-07,
carry none: capture anew).

A capture takes as long as the diagnosis (3-5 minutes for 240 cases on 2
cores), a replay of one set a few seconds. No timing is reported.
"""

import argparse
import json
import pickle
from pathlib import Path


def capture(items: list, fitted: list[bool]) -> list[tuple]:
    """`(prep, fit, named effect)` of each of `diagnose_many`'s `items`, in
    order: one call, the rule's inputs kept as it is applied."""
    from hamjax.diagnosis import attribute as at
    from hamjax.diagnosis.diagnose import RULES, diagnose_many

    pending, kept = [], {}

    def keep_inputs(prep, fit):
        pending.append((prep, fit))
        return at.attribute(prep, fit)

    def keep(i, diagnosis):  # called right after the rule, case by case
        kept[i] = (*pending.pop(), diagnosis.effect)

    RULES["capture"] = keep_inputs
    try:
        diagnose_many(items, rule="capture", on_result=keep, fitted=fitted)
    finally:
        RULES.pop("capture")
    return [kept[i] for i in range(len(items))]


def _with_own_nominal(cases: list[tuple]) -> tuple[list, list[bool]]:
    """`diagnose_many`'s items of `(model or None, dt, estimation, validation)`
    cases, hamjax's own nominal (`fit_nominal_many`, one batch, as `hamjax
    diagnose` fits it) where the model is None, and which ones it fitted."""
    from hamjax.diagnosis.nominal_fit import fit_nominal_many

    own = [i for i, (model, *_) in enumerate(cases) if model is None]
    plants = fit_nominal_many([(cases[i][1], cases[i][2]) for i in own])
    fitted_plant = dict(zip(own, plants, strict=True))
    items = [
        (fitted_plant[i] if model is None else model, dt, est, val)
        for i, (model, dt, est, val) in enumerate(cases)
    ]
    return items, [model is None for model, *_ in cases]


def loop_cases(
    seed: int, n_cases: int, *, sticky_only: bool = False
) -> dict[int, dict]:
    """`{index: case}` of the seed's loops of the benchmark
    (`papers.gap.control_loops`, the same draws as `hamjax blind make --family
    loops`), or of its sticky ones only."""
    from hamjax.papers.gap import control_loops as cl

    cases = {
        i: cl.make_case(seed, i, s) for i, s in enumerate(cl.slots_for(seed, n_cases))
    }
    if sticky_only:
        return {i: c for i, c in cases.items() if c["truth"]["effect"] == "backlash"}
    return cases


def diagnose_captured(cases: list[dict]) -> list[tuple]:
    """`(truth, prep, fit, named effect)` of each loop, in order: diagnosed in one
    call without model.json (hamjax fits its own nominal), the fits captured
    (`capture`)."""
    items, fitted = _with_own_nominal(
        [(None, c["truth"]["dt"], c["estimation"], c["validation"]) for c in cases]
    )
    kept = capture(items, fitted)
    return [(c["truth"], *k) for c, k in zip(cases, kept, strict=True)]


def _set_items(folder: Path) -> tuple[list, list, list, list]:
    """Names, truths, `diagnose_many` items and fitted flags of a blind set's
    cases (hamjax's own nominal for a case without model.json)."""
    from hamjax.diagnosis.case import read_case

    truth = json.loads((folder / "truth.json").read_text())["cases"]
    folders = sorted(p for p in (folder / "cases").iterdir() if p.is_dir())
    cases = [read_case(f) for f in folders]
    items, fitted = _with_own_nominal(
        [(c.model, c.dt, c.estimation, c.validation) for c in cases]
    )
    names = [f.name for f in folders]
    return names, [truth[n] for n in names], items, fitted


def _loop_items(seed: int, n_cases: int) -> tuple[list, list]:
    """Names and `(truth, prep, fit, named)` of the seed's loops, captured
    (`diagnose_captured`)."""
    cases = loop_cases(seed, n_cases)
    order = sorted(cases)
    kept = diagnose_captured([cases[i] for i in order])
    return [f"case_{i:04d}" for i in order], kept


def _score(path: Path, rule: str) -> tuple[dict, str]:
    from hamjax.diagnosis.diagnose import RULES, attribution_probabilities
    from hamjax.diagnosis.probabilities import STICTION_LIKE
    from hamjax.papers.gap.blind import calibration

    data = pickle.loads(path.read_bytes())
    named, confidence = {}, {}
    for n, (_, prep, fit, _) in data.items():
        att = RULES[rule](prep, fit)
        named[n] = att.effect
        confidence[n] = attribution_probabilities(att)[att.effect]
    truth = {n: entry[0]["effect"] for n, entry in data.items()}
    right = sum(named[n] == truth[n] for n in named)
    nones = [n for n in named if truth[n] == "none"]
    ece = calibration(
        [confidence[n] for n in named], [named[n] == truth[n] for n in named]
    )["ece"]
    line = (
        f"{path.name}: accuracy {right / len(named):.3f} ({right} of {len(named)}), "
        f"false alarm on none {sum(named[n] != 'none' for n in nones)} of {len(nones)}"
        f", ECE {ece:.3f}"
    )
    if all("stiction" in entry[0] for entry in data.values()):  # control loops
        sticky = [n for n in named if truth[n] == "backlash"]
        other = [n for n in named if truth[n] != "backlash"]
        hits = sum(named[n] in STICTION_LIKE for n in sticky)
        alarms = sum(named[n] in STICTION_LIKE for n in other)
        line += (
            f"; stiction recall {hits} of {len(sticky)}, false alarm {alarms} of "
            f"{len(other)}"
        )
    return named, line


def _fits_report(path: Path) -> str:
    """What the captured fits of `path` show, no rule applied: the prediction-error
    rows that nest the re-fit (free all of its slots and more) yet end above its
    one-step SSE (and their median likelihood ratio), the cases with a
    prediction-error row whose linear part has a pole beyond 1 + 1e-6, and the
    cases whose re-fit simulates validation worse than the nominal (with how
    many of them were named wrong)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from hamjax.diagnosis.augmented import filter_coefficients
    from hamjax.diagnosis.layout import finite_sse, n_beyond, validation_sse
    from hamjax.diagnosis.schedule import leading_rows
    from hamjax.models.linear._base import companion_roots

    coefficients = jax.jit(filter_coefficients)
    data = pickle.loads(path.read_bytes())
    whitened = nesting = above = unstable = worse = worse_wrong = 0
    lrs, radii = [], []
    for truth, prep, fit, named in data.values():
        refit = leading_rows(prep, fit)[2]
        nominal = np.sum(
            (np.asarray(prep.arrays.y_val)[: prep.n_val] - prep.w_val) ** 2
        )
        if validation_sse(prep, fit)[refit] > nominal:
            worse += 1
            worse_wrong += named != truth["effect"]
        white = fit.get("whitened")
        if white is None:
            continue
        whitened += 1
        sse = finite_sse(white)
        for k in white["rows"]:
            # row k nests the re-fit: frees all of its slots, and more
            nests = n_beyond(prep, refit, k) == 0 and n_beyond(prep, k, refit) > 0
            if k == refit or not nests:
                continue
            nesting += 1
            if sse[k] > sse[refit]:
                above += 1
                lrs.append((sse[refit] - sse[k]) / sse[k] * prep.n_est)
        radius = 0.0
        for k in white["rows"]:
            a = np.trim_zeros(
                np.asarray(
                    coefficients(jnp.asarray(white["params"][k]), prep.arrays)[1]
                ),
                "b",
            )
            if a.shape[0] > 1:
                roots = companion_roots(a[1:] / a[0], xp=np)
                radius = max(radius, float(np.max(np.abs(roots))))
        if radius > 1 + 1e-6:
            unstable += 1
            radii.append(radius)
    median = f"{np.median(lrs):.1f}" if lrs else "-"
    top = f", up to {max(radii):.4f}" if radii else ""
    return (
        f"{path.name}: {len(data)} cases, {whitened} fitted by prediction error; "
        f"nesting rows above the re-fit {above} of {nesting} (median likelihood "
        f"ratio {median}); cases with a prediction-error pole beyond 1 + 1e-6 "
        f"{unstable}{top}; re-fit validating worse than the nominal {worse} "
        f"({worse_wrong} of them named wrong)"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    cap = sub.add_parser("capture", help="diagnose once, keep the rule's inputs")
    what = cap.add_mutually_exclusive_group(required=True)
    what.add_argument("--set", type=Path, help="a blind set (truth.json, cases/)")
    what.add_argument("--loops", type=int, metavar="SEED", help="control loops")
    cap.add_argument("--cases", type=int, default=80, help="loops per seed")
    cap.add_argument("--out", type=Path, required=True)
    score = sub.add_parser("score", help="replay the installed rule")
    score.add_argument("fits", type=Path, nargs="+")
    score.add_argument("--rule", default="cascade")
    score.add_argument("--names", type=Path, help="write every case's name here")
    score.add_argument("--against", type=Path, help="names written earlier")
    report = sub.add_parser("fits", help="what the captured fits show, no rule")
    report.add_argument("fits", type=Path, nargs="+")
    args = parser.parse_args(argv)

    import hamjax
    from hamjax._runtime import same_rounding_in_every_lane, split_cpu_into_devices

    split_cpu_into_devices()
    same_rounding_in_every_lane()  # as `hamjax` runs
    hamjax.enable_x64()
    from hamjax.diagnosis.diagnose import RULES

    if args.command == "score" and args.rule not in RULES:
        parser.error(f"--rule {args.rule}: one of {', '.join(sorted(RULES))}")
    if args.command == "capture":
        if args.out.exists():
            parser.error(f"{args.out} exists: not overwritten")
        if args.set is not None:
            names, truths, items, fitted = _set_items(args.set)
            captured = capture(items, fitted)
            kept = [(t, *k) for t, k in zip(truths, captured, strict=True)]
        else:
            names, kept = _loop_items(args.loops, args.cases)
        store = dict(zip(names, kept, strict=True))
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_bytes(pickle.dumps(store))
        print(f"{args.out}: {len(store)} cases captured")
        return
    if args.command == "fits":
        for path in args.fits:
            print(_fits_report(path))
        return
    before = json.loads(args.against.read_text()) if args.against else {}
    every = {}
    for path in args.fits:
        named, line = _score(path, args.rule)
        every[path.name] = named
        print(line)
        for n, effect in named.items():
            old = before.get(path.name, {}).get(n)
            if old is not None and old != effect:
                print(f"    {n}: {old} -> {effect}")
    if args.names:
        args.names.write_text(json.dumps(every, indent=1))


if __name__ == "__main__":
    main()
