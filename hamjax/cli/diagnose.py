"""`hamjax diagnose CASE... --out DIR`: name the effect behind a sim-to-real gap."""

import argparse
import sys
import time
from pathlib import Path

from .._argtypes import positive_float


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
    p.set_defaults(func=run)


def _plan(args: argparse.Namespace) -> tuple[list[Path], list]:
    """Output folders of the cases (in input order) and the earlier results to
    clear; refuses a bad --out before any case is read."""
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
    names, notes = unique_names(args.cases, args.out)
    for note in notes:
        print(f"hamjax: note: {note}", file=sys.stderr)
    return [args.out / n for n in names], earlier


def _read_cases(args: argparse.Namespace, outs: list[Path]) -> tuple[list, int]:
    """`(index, case, out)` of the cases that read; a bad case stops a single-case
    run and is reported and skipped in a multi-case one."""
    from .._errors import UserInputError
    from ..diagnosis.case import read_case

    good, failed = [], 0
    for i, (folder, out) in enumerate(zip(args.cases, outs, strict=True)):
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


def run(args: argparse.Namespace) -> int:
    from .._runtime import split_cpu_into_devices

    split_cpu_into_devices()  # before the first computation
    from .._errors import UserInputError
    from ..diagnosis.diagnose import DiagnosisNotFinite, diagnose_many
    from ..diagnosis.nominal_fit import fit_nominal
    from ..diagnosis.report import write_diagnosis
    from ..io import model_to_dict, write_json
    from ._outputs import remove_files

    quiet, verbose = getattr(args, "quiet", False), getattr(args, "verbose", False)
    start = time.perf_counter()
    outs, earlier = _plan(args)
    cases, failed = _read_cases(args, outs)
    if cases and earlier:
        n = remove_files(earlier, args.out)
        if verbose:
            print(
                f"removed {n} earlier result file(s) from {args.out}", file=sys.stderr
            )
    items, where = [], []
    for _, case, out in cases:
        plant = case.model
        if plant is None:
            plant = fit_nominal(case.dt, case.estimation)
            write_json(out / "nominal_model.json", model_to_dict(plant, case.dt))
            source = "fitted by hamjax on the estimation record (nominal_model.json)"
        else:
            source = f"given ({case.folder / 'model.json'})"
        items.append((plant, case.dt, case.estimation, case.validation))
        name = out.name if len(outs) > 1 else case.name
        where.append((case.folder, out, name, source))
    printer = _InOrder(quiet, len(items))

    def write(i, d):  # each case is written as soon as its chunk is done
        folder, out, name, source = where[i]
        write_diagnosis(d, out, name, nominal=source)
        if args.figures:
            from ..plotting.diagnosis import save_diagnosis_figures

            save_diagnosis_figures(d, out, name)
        printer.add(i, _line(name, d, verbose))

    if items:
        try:
            prior = {}
            if args.nominal_uncertainty is not None:
                prior["nominal_uncertainty"] = args.nominal_uncertainty
            diagnose_many(
                items,
                on_result=write,
                rule=args.rule,
                **prior,
            )
        except DiagnosisNotFinite as err:
            raise UserInputError(f"{where[err.index][0]}: {err}") from None
        except ValueError as err:
            raise UserInputError(
                f"{args.cases[0] if len(args.cases) == 1 else 'cases'}: {err}"
            ) from None
        finally:
            printer.close()
    if not quiet:
        print(
            f"diagnosed {len(items)} case(s) in {time.perf_counter() - start:.1f} s",
            file=sys.stderr,
        )
    return 2 if failed else 0
