"""`hamjax diagnose CASE... --out DIR`: name the effect behind a sim-to-real gap."""

import argparse
import sys
import time
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="diagnose the sim-to-real gap of one or more case folders",
        description="Each CASE folder holds estimation.csv, validation.csv (t,v,y) and "
        "optionally model.json (see contracts/gap-case.md). One case writes "
        "OUT/diagnosis.json; several write OUT/<case name>/diagnosis.json.",
    )
    p.add_argument("cases", nargs="+", type=Path, metavar="CASE")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--figures", action="store_true", help="also write the figures")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .._runtime import split_cpu_into_devices

    split_cpu_into_devices()  # before the first computation
    from .._errors import UserInputError
    from ..diagnosis.case import read_case
    from ..diagnosis.diagnose import diagnose_many
    from ..diagnosis.nominal_fit import fit_nominal
    from ..diagnosis.report import write_diagnosis
    from ..io import model_to_dict, write_json

    start = time.perf_counter()
    single = len(args.cases) == 1
    items, names, failed = [], [], 0
    for folder in args.cases:
        try:
            case = read_case(folder)
            out = args.out if single else args.out / case.name
            plant = case.model
            if plant is None:
                plant = fit_nominal(case.dt, case.estimation)
                write_json(out / "nominal_model.json", model_to_dict(plant, case.dt))
            items.append((plant, case.dt, case.estimation, case.validation))
            names.append((case.name, out))
        except UserInputError as err:
            if single:
                raise
            print(f"hamjax: error: {err}", file=sys.stderr)
            failed += 1
    if items:

        def write(i, d):  # each case is written as soon as its chunk is done
            name, out = names[i]
            write_diagnosis(d, out, name)
            if args.figures:
                from ..plotting.diagnosis import save_diagnosis_figures

                save_diagnosis_figures(d, out)
            if not args.quiet:
                print(
                    f"{name}: {d.effect} (gap {d.gap_before:.4g} -> {d.gap_after:.4g}, "
                    f"noise {d.noise_floor:.4g})"
                )

        try:
            diagnose_many(items, on_result=write)
        except ValueError as err:
            raise UserInputError(
                f"{args.cases[0] if single else 'cases'}: {err}"
            ) from None
    if not args.quiet:
        n = len(items)
        print(
            f"diagnosed {n} case(s) in {time.perf_counter() - start:.1f} s",
            file=sys.stderr,
        )
    return 2 if failed else 0
