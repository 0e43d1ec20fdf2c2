"""Recursive PL (seed 001): impulse experiment (5.1), gradient identification (4.1).

`hamjax experiment recursive-pl` writes experiment.json + input.csv,
`hamjax identify recursive-pl DIR` writes result.json (contract
`contracts/experiments.md`), `hamjax reproduce recursive-pl --out DIR` reproduces
Section V.C of Giri, Rochdi, Chaoui (`hamjax/papers/seed001/section_vc.py`).
"""

import argparse
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..._errors import UserInputError
from ..._results import RESULTS
from ...identification.seed001 import (
    STRUCTURES,
    check_levels,
    identify_recursive_pl,
)
from ...io import read_data, read_design, write_csv, write_json
from ...io.results import recursive_pl_result_dict
from ...signals import pe_impulse_sequence
from .._common import (
    add_data_folder,
    add_experiment_folder,
    add_levels,
    add_sampling_period,
    positive_float,
    positive_int,
)
from .._methods import result_path


# ----------------------------------------------------------------------------- design


def add_experiment_arguments(p: argparse.ArgumentParser) -> None:
    add_levels(
        p,
        help="V1,V2,V3,V4 with V1 < V2 < -D_M < 0 < D_M < V3 < V4 (--levels=-6,-3,3,6)",
    )
    p.add_argument("--order", type=positive_int, required=True, help="order n (A1)")
    p.add_argument(
        "--periods", type=positive_int, required=True, help="periods T = 7n of (5.1)"
    )
    add_sampling_period(p, help="sampling period")
    p.add_argument(
        "--d-max",
        type=positive_float,
        default=None,
        help="the bound D_M of A4, to check (3.1) (optional)",
    )
    add_experiment_folder(p)


def experiment(args: argparse.Namespace) -> int:
    levels = _levels(args.levels, args.d_max, "--levels")
    design = {
        "method": "recursive-pl",
        "dt": args.dt,
        "levels": levels,
        "order": args.order,
        "periods": args.periods,
        "d_max": args.d_max,
        "period_samples": 7 * args.order,
        "n_samples": 7 * args.order * args.periods,
        "note": "input.csv = the impulse sequence (5.1) of period T = 7n, values in "
        "{0, V1..V4}; the plant must start at rest; no initialisation part",
    }
    t, v = designed_input(design)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "experiment.json", design)
    write_csv(args.out / "input.csv", {"t": t, "v": v})
    print(f"wrote {args.out / 'experiment.json'} and input.csv ({t.shape[0]} samples)")
    return 0


def _levels(levels, d_max, what: str) -> list[float]:
    try:
        return [float(x) for x in np.asarray(check_levels(levels, d_max=d_max))]
    except ValueError as err:
        raise UserInputError(f"{what}: {err}") from None


def designed_input(design: dict) -> tuple[np.ndarray, np.ndarray]:
    """(t, v) of (5.1) for an experiment.json design."""
    try:
        _, v = pe_impulse_sequence(
            jnp.asarray(design["levels"], dtype=float),
            order=int(design["order"]),
            periods=int(design["periods"]),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise UserInputError(
            f"experiment.json: bad recursive-pl design ({err})"
        ) from None
    v = np.asarray(v)
    return np.arange(v.shape[0]) * float(design["dt"]), v


# ----------------------------------------------------------------------------- identify


def add_identify_arguments(p: argparse.ArgumentParser) -> None:
    add_data_folder(p)
    p.add_argument(
        "--structure",
        choices=STRUCTURES,
        default=None,
        help="rule of (3.18) for D and L: dead-zone (a), preload (b), symmetric (c); "
        "without it d1, d2, l1, l2 are null",
    )
    p.add_argument(
        "--rho",
        type=positive_float,
        default=1e6,
        help="projection radius rho* >= ||Theta*|| of (4.1a) (default 1e6)",
    )
    p.add_argument(
        "--estimator",
        choices=("gradient", "batch"),
        default="gradient",
        help="the paper's normalised gradient (4.1) or batch least squares",
    )
    p.add_argument(
        "--refine",
        action="store_true",
        help="add an output-error refinement (optimistix) of the closed form, with "
        "standard errors from the Fisher information, under 'refined'",
    )


def identify(args: argparse.Namespace) -> int:
    out = result_path(args)
    folder: Path = args.dir
    design = read_design(folder, "recursive-pl", ("dt", "levels", "order", "periods"))
    _, v = designed_input(design)
    levels = _levels(design["levels"], design.get("d_max"), f"{folder}/experiment.json")
    y = read_data(folder, design, v)
    try:
        res = identify_recursive_pl(
            v,
            y,
            levels=levels,
            order=int(design["order"]),
            structure=args.structure,
            rho=args.rho,
            estimator=args.estimator,
            keep_history=False,
            throw=False,
        )
    except ValueError as err:
        raise UserInputError(f"{folder / 'data.csv'}: {err}") from None
    code = res.result
    if code in (RESULTS.nonfinite, RESULTS.not_exciting):
        raise UserInputError(f"{folder / 'data.csv'}: {RESULTS[code]}")
    result = recursive_pl_result_dict(res, rho=args.rho, estimator=args.estimator)
    # The closed form is written first, so a failing refinement loses nothing.
    write_json(out, result)
    print(f"wrote {out}")
    if getattr(args, "refine", False):
        from ...refinement import refine_recursive_pl_result

        refined = refine_recursive_pl_result(
            v,
            y,
            result,
            levels=levels,
            order=int(design["order"]),
            structure=args.structure,
        )
        result.update(refined)
        write_json(out, result)
        state = "converged" if refined["converged"] else "did NOT converge"
        print(f"refinement {state}; added 'refined' and 'standard_errors'")
    if not result["consistent"]:
        print(
            f"hamjax: warning: the estimates are inconsistent with the named structure "
            f"{args.structure!r} (see result.json 'consistent')",
            file=sys.stderr,
        )
    if code in (RESULTS.degenerate, RESULTS.constrained):
        # Written (nothing is lost), but never called successful: exit 1.
        print(
            f"hamjax: error: {out}: result {result['result']}: {RESULTS[code]}",
            file=sys.stderr,
        )
        return 1
    return 0


# ----------------------------------------------------------------------------- reproduce


def add_reproduce_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument(
        "--periods",
        type=positive_int,
        default=2000,
        help="periods T = 14 of (5.1) (default 2000: 28000 samples)",
    )


def reproduce(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    from ...papers.seed001.section_vc import write_section_vc

    args.out.mkdir(parents=True, exist_ok=True)
    summary, made = write_section_vc(args.out, periods=args.periods)
    print(f"wrote {', '.join(name for name, _ in made)} to {args.out}")
    for line in summary["headline"]:
        print(line)
    return 0
