"""`hamjax diagnose CASE... --out DIR`: name the effect behind a sim-to-real gap."""

import argparse
import sys
import time
from pathlib import Path
from typing import NamedTuple

from .._argtypes import positive_float
from ._common import add_cluster_arguments, start_cluster


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="diagnose the sim-to-real gap of one or more case folders",
        description="Each CASE folder holds estimation.csv, validation.csv (t,v,y) and "
        "optionally model.json (see docs/gap-case-folder.md). One case writes "
        "OUT/diagnosis.json; several write OUT/<case name>/diagnosis.json (a name "
        "given twice gets -2, -3, ...). An OUT that already holds results is "
        "refused unless --force, which removes them first.",
    )
    p.add_argument("cases", nargs="+", type=Path, metavar="CASE")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--figures", action="store_true", help="also write the figures")
    p.add_argument(
        "--nominal-uncertainty",
        type=positive_float,
        metavar="U",
        help="relative std of the nominal model's parameters: every re-fit is a "
        "maximum-a-posteriori fit under a Gaussian prior at nominal of this width "
        "(default: hamjax.diagnosis.layout.NOMINAL_UNCERTAINTY, 0.2)",
    )
    p.add_argument(
        "--rule",
        choices=("cascade", "likelihood"),
        default="cascade",
        help="the decision rule: 'cascade' (hamjax.diagnosis.attribute, the default) "
        "or 'likelihood' (hamjax.diagnosis.decide: every candidate with its noise "
        "model, judged by one held-out predictive log-likelihood)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace the results of an earlier diagnosis in OUT",
    )
    add_cluster_arguments(
        p,
        how="the cases are split over the processes (the cases sorted by path are "
        "cut into blocks of hamjax.diagnosis.diagnose.CASES_PER_CALL, block b to "
        "process b mod N; every block one call padded as the whole run), so that a "
        "case's numbers depend only on the case list, not on N; each writes the "
        "cases it owns into OUT, process 0 prints the summary",
    )
    p.set_defaults(func=run)


def share(cases: list[Path], *, num_processes: int, process_id: int) -> list[list[int]]:
    """The blocks of the `cases` (indices) that process `process_id` of
    `num_processes` diagnoses, one `diagnose_many` call each: the cases sorted by
    path (then by position, for a path given twice) and cut into
    `diagnosis.diagnose.run_blocks`; block `b` to process `b mod num_processes`.
    The blocks follow from the case list alone, so a case's numbers do not depend
    on the number of processes."""
    from ..diagnosis.diagnose import run_blocks

    order = sorted(range(len(cases)), key=lambda i: (str(cases[i]), i))
    blocks = [[order[k] for k in b] for b in run_blocks(len(order))]
    return blocks[process_id::num_processes]


def _sizes(folder: Path) -> tuple | None:
    """`(nominal or None, longer record's length)` of a case, read cheaply (the
    records' row counts and model.json, no fit), for `run_padding`; None where
    they do not read (the case's owner reports it and skips it)."""
    from .._errors import UserInputError
    from ..io import count_rows, load_model

    try:
        n = max(
            count_rows(folder / f"{name}.csv") for name in ("estimation", "validation")
        )
        model = folder / "model.json"
        return (load_model(model)[0] if model.exists() else None), n
    except UserInputError:
        return None


def padding(cases: list[Path], read: dict | None = None):
    """`run_padding` of the run: the same on every process, whatever their
    number (from the whole case list, never from a fit). `read`: `_sizes` of the
    cases already read, by folder (so that they are not read twice)."""
    from ..diagnosis.diagnose import run_padding

    read = read or {}
    folders = sorted(set(cases), key=str)
    sizes = [read[f] if f in read else _sizes(f) for f in folders]
    return run_padding(s for s in sizes if s is not None)


def _plan(args: argparse.Namespace, *, notes: bool) -> tuple[list[Path], list]:
    """Output folders of the cases (in input order) and the earlier results to
    clear; refuses a bad --out before any case is read. `notes`: print the notes
    on renamed outputs."""
    from ._outputs import (
        check_output_folder,
        earlier_diagnosis,
        refuse_unless_forced,
        unique_names,
    )

    check_output_folder(args.out)
    earlier = earlier_diagnosis(args.out)
    refuse_unless_forced(args.out, earlier, args.force, "diagnosis results")
    if len(args.cases) == 1:
        return [args.out], earlier
    names, renamed = unique_names(args.cases, args.out)
    for note in renamed if notes else ():
        print(f"hamjax: note: {note}", file=sys.stderr)
    return [args.out / n for n in names], earlier


def _read_cases(
    args: argparse.Namespace, outs: list[Path], mine: list[int]
) -> tuple[list, int]:
    """`(index, case, out)` of the cases `mine` that read; a bad case stops a
    single-case run and is reported and skipped in a multi-case one."""
    from .._errors import UserInputError
    from ..diagnosis.case import read_case

    good, failed = [], 0
    for i in sorted(mine):
        folder, out = args.cases[i], outs[i]
        try:
            good.append((i, read_case(folder), out))
        except UserInputError as err:
            if len(args.cases) == 1:
                raise
            print(f"hamjax: error: {err}", file=sys.stderr)
            failed += 1
    return good, failed


class _InOrder:
    """Prints per-case lines in input order as cases finish in any order, with a
    progress bar of finished cases on a terminal's stderr (none with --quiet)."""

    def __init__(self, quiet: bool, total: int):
        from ..montecarlo.progress import progress_bar

        self.quiet = quiet
        self.lines: dict[int, str] = {}
        self.next = 0
        self.bar = progress_bar(
            total=total, initial=0, name="diagnose", quiet=quiet, unit="case"
        )

    def add(self, i: int, line: str) -> None:
        self.lines[i] = line
        self.bar.update(1)
        while self.next in self.lines:
            if not self.quiet:
                self.bar.write(self.lines.pop(self.next))
            self.next += 1

    def close(self) -> None:
        self.bar.close()


def _line(name: str, d, verbose: bool) -> str:
    line = (
        f"{name}: {d.effect} (gap {d.gap_before:.4g} -> {d.gap_after:.4g}, "
        f"noise {d.noise_floor:.4g})"
    )
    if verbose:
        line += "\n" + "\n".join(
            f"  {c['effect']}: gap after {c['gap_after']:.4g}" for c in d.ranking[:3]
        )
    return line


def _fingerprint(args: argparse.Namespace) -> int:
    """What every process must be given alike: the cases in order and the options
    that change a diagnosis or its outputs."""
    from ..montecarlo.distributed import fingerprint

    options = (
        args.rule,
        args.nominal_uncertainty,
        args.figures,
        args.force,
    )
    return fingerprint([*map(str, args.cases), str(args.out), repr(options)])


def _start(args: argparse.Namespace, me: int) -> tuple[list[Path], list]:
    """`_plan` on every process, checked together: the same cases and options
    everywhere, and no process refusing its --out (else all stop, in one line)."""
    from .._errors import UserInputError
    from ..montecarlo.distributed import allgather_ints

    try:
        plan, problem = _plan(args, notes=me == 0), None
    except UserInputError as err:
        plan, problem = ([], []), err
    status = allgather_ints([_fingerprint(args), problem is not None])
    differ = [p for p in range(len(status)) if status[p, 0] != status[0, 0]]
    if differ:
        raise UserInputError(
            f"process {differ[0]} was given other cases or options than process 0 "
            "(CASE..., --out, --rule, --nominal-uncertainty, --figures "
            "and --force must be the same on every process)"
        )
    if problem is not None:
        raise problem
    refused = [p for p in range(len(status)) if status[p, 1]]
    if refused:
        raise UserInputError(f"process {refused[0]} refused its --out (see its error)")
    return plan


def _clear(args, earlier: list, any_read: bool, me: int, n_proc: int, verbose) -> None:
    """--force: remove the earlier results, when some case read (`any_read` and
    --force alike on every process). With several processes, process 0 first,
    then each other one what it still sees (its own --out when it is not
    shared), and only then does any process write."""
    from ..montecarlo.distributed import allgather_ints
    from ._outputs import earlier_diagnosis, remove_files

    if not (args.force and any_read):
        return
    n = remove_files(earlier, args.out) if me == 0 else 0
    if n_proc > 1:
        allgather_ints([0])  # process 0 has removed its files
        if me != 0:
            n = remove_files(earlier_diagnosis(args.out), args.out)
        allgather_ints([0])  # every process has
    if n and verbose:
        print(f"removed {n} earlier result file(s) from {args.out}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from .._runtime import same_rounding_in_every_lane, split_cpu_into_devices

    split_cpu_into_devices()  # before the first computation
    same_rounding_in_every_lane()  # likewise
    start_cluster(args)
    import jax

    from .._errors import UserInputError
    from ..montecarlo.distributed import allgather_ints

    quiet, verbose = getattr(args, "quiet", False), getattr(args, "verbose", False)
    start = time.perf_counter()
    me, n_proc = jax.process_index(), jax.process_count()
    outs, earlier = _start(args, me)
    blocks = share(args.cases, num_processes=n_proc, process_id=me)
    error, done, failed = None, 0, 0
    try:
        cases, failed = _read_cases(args, outs, [i for b in blocks for i in b])
    except UserInputError as err:  # one case, unreadable: every process stops
        error, cases = err, []
    any_read = allgather_ints([len(cases), error is not None])
    if any_read[:, 1].any():
        if error is not None:
            raise error
        raise UserInputError("process 0 could not read the case (see its error)")
    _clear(args, earlier, bool(any_read[:, 0].any()), me, n_proc, verbose)
    try:
        done = _diagnose(args, cases, outs, blocks, quiet, verbose)
    except Exception as err:  # noqa: BLE001 -- re-raised once every process knows
        error = err
    totals = allgather_ints([done, failed, error is not None])
    if error is not None:
        raise error
    if me != 0:
        return 2 if failed else 0
    crashed = [p for p in range(n_proc) if totals[p, 2]]
    if crashed:
        raise UserInputError(f"process {crashed[0]} stopped (see its error)")
    if not quiet:
        over = f" over {n_proc} processes" if n_proc > 1 else ""
        print(
            f"diagnosed {totals[:, 0].sum()} case(s){over} in "
            f"{time.perf_counter() - start:.1f} s",
            file=sys.stderr,
        )
    return 2 if totals[:, 1].any() else 0


# the report's line for a case without model.json (and the flag `diagnose_many` gets)
FITTED = "fitted by hamjax on the estimation record (nominal_model.json)"


class _Where(NamedTuple):
    """Where a case comes from and goes: its folder, its output folder, the name
    it is written under, its nominal's source in words, and whether hamjax fitted
    that nominal."""

    folder: Path
    out: Path
    name: str
    source: str
    fitted: bool


def _diagnose(args, cases: list, outs, blocks, quiet, verbose) -> int:
    """Diagnose the cases read (`(index, case, out)`), one `diagnose_many` call per
    block of `blocks` (`share`) padded as the whole run (`padding`), writing each
    case as soon as it is done; the number diagnosed."""
    from ..diagnosis.nominal_fit import describe_structure, fit_nominal_many
    from ..io import model_to_dict, write_json

    # every nominal that hamjax fits itself, in one batch (`fit_nominal_many`)
    unfitted = [(i, case) for i, case, _ in cases if case.model is None]
    if unfitted and not quiet:
        print(
            f"fitting the nominal model of {len(unfitted)} case(s) without "
            "model.json ...",
            file=sys.stderr,
        )
    nominals = fit_nominal_many([(case.dt, case.estimation) for _, case in unfitted])
    fitted = {i: plant for (i, _), plant in zip(unfitted, nominals, strict=True)}
    item, where, read = {}, {}, {}
    for i, case, out in cases:
        n = max(case.estimation["v"].shape[0], case.validation["v"].shape[0])
        read[args.cases[i]] = (case.model, n)  # as `_sizes` reads it
        plant = case.model
        if plant is None:
            plant = fitted[i]
            write_json(out / "nominal_model.json", model_to_dict(plant, case.dt))
            source = f"{FITTED}: {describe_structure(plant)}"
        else:
            source = f"given ({case.folder / 'model.json'})"
        item[i] = (plant, case.dt, case.estimation, case.validation)
        name = out.name if len(outs) > 1 else case.name
        where[i] = _Where(case.folder, out, name, source, case.model is None)
    if not item:
        return 0
    calls = [[i for i in b if i in item] for b in blocks]
    # lines per block, in input order within it
    lines = [i for members in calls for i in sorted(members)]
    rank = {i: k for k, i in enumerate(lines)}
    printer = _InOrder(quiet, len(item))
    pad = padding(args.cases, read)
    try:
        for members in filter(None, calls):
            _call(
                args,
                members,
                item,
                where,
                pad,
                lambda i, line: printer.add(rank[i], line),
                verbose,
            )
    finally:
        printer.close()
    return len(item)


def _call(
    args, members: list[int], item: dict, where: dict[int, _Where], pad, show, verbose
) -> None:
    """One block: `diagnose_many` of the cases `members` (in block order) with the
    run's padding `pad`; each case written as soon as it is done and its line
    passed to `show(i, line)`."""
    from .._errors import UserInputError
    from ..diagnosis.diagnose import DiagnosisNotFinite, diagnose_many
    from ..diagnosis.report import write_diagnosis

    prior = {}
    if args.nominal_uncertainty is not None:
        prior["nominal_uncertainty"] = args.nominal_uncertainty

    def write(j, d):  # each case as soon as it is done
        w = where[members[j]]
        write_diagnosis(d, w.out, w.name, nominal=w.source)
        if args.figures:
            from ..plotting.diagnosis import save_diagnosis_figures

            save_diagnosis_figures(d, w.out, w.name)
        show(members[j], _line(w.name, d, verbose))

    try:
        diagnose_many(
            [item[i] for i in members],
            fitted=[where[i].fitted for i in members],
            on_result=write,
            rule=args.rule,
            padding=pad,
            **prior,
        )
    except DiagnosisNotFinite as err:
        raise UserInputError(f"{where[members[err.index]].folder}: {err}") from None
    except ValueError as err:
        raise UserInputError(
            f"{args.cases[0] if len(args.cases) == 1 else 'cases'}: {err}"
        ) from None
