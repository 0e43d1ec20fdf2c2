"""Recursive PL (seed 001): impulse experiment (5.1), gradient identification (4.1).

`hamjax experiment recursive-pl` writes experiment.json + input.csv,
`hamjax identify recursive-pl DIR` writes result.json (contract
`contracts/experiments.md`), `hamjax reproduce recursive-pl --out DIR` reproduces
Section V.C of Giri, Rochdi, Chaoui (Fig. 3a/3b analogues + numbers).
"""

import argparse
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..._errors import UserInputError
from ..._results import RESULTS
from ...identification.recursive_pl import (
    STRUCTURES,
    check_levels,
    identify_recursive_pl,
    recover_history,
)
from ...io import read_data, read_design, write_csv, write_json
from ...signals import pe_impulse_sequence
from .._common import float_list, positive_float, positive_int


# ----------------------------------------------------------------------------- design


def add_experiment_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--levels",
        type=float_list,
        required=True,
        help="V1,V2,V3,V4 with V1 < V2 < -D_M < 0 < D_M < V3 < V4 (--levels=-6,-3,3,6)",
    )
    p.add_argument("--order", type=positive_int, required=True, help="order n (A1)")
    p.add_argument(
        "--periods", type=positive_int, required=True, help="periods T = 7n of (5.1)"
    )
    p.add_argument("--dt", type=positive_float, required=True, help="sampling period")
    p.add_argument(
        "--d-max",
        type=positive_float,
        default=None,
        help="the bound D_M of A4, to check (3.1) (optional)",
    )
    p.add_argument("--out", type=Path, required=True, help="experiment folder")


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
    p.add_argument("dir", type=Path, help="experiment folder with data.csv")
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
    result = result_dict(res, rho=args.rho, estimator=args.estimator)
    # The closed form is written first, so a failing refinement loses nothing.
    write_json(folder / "result.json", result)
    print(f"wrote {folder / 'result.json'}")
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
        write_json(folder / "result.json", result)
        state = "converged" if refined["converged"] else "did NOT converge"
        print(f"refinement {state}; added 'refined' and 'standard_errors'")
    if not result["consistent"]:
        print(
            f"hamjax: warning: the estimates are inconsistent with the named structure "
            f"{args.structure!r} (see result.json 'consistent')",
            file=sys.stderr,
        )
    return 0


def result_dict(res, *, rho: float, estimator: str) -> dict:
    """result.json of the contract from a `RecursivePLResult`."""
    e = res.estimate
    named = res.structure is not None

    def num(x):
        return float(x) if named else None

    levels = np.asarray(res.levels)
    return {
        "method": "recursive-pl",
        "a": np.asarray(e.a).tolist(),
        "b": np.asarray(e.b).tolist(),
        "points": [
            [float(vj), float(fj)] for vj, fj in zip(levels, e.points, strict=True)
        ],
        "k1": float(e.k1),
        "k2": float(e.k2),
        "h1": float(e.h1),
        "h2": float(e.h2),
        "d1": num(e.d1),
        "d2": num(e.d2),
        "l1": num(e.l1),
        "l2": num(e.l2),
        "structure": res.structure,
        "consistent": bool(e.consistent),
        "result": RESULTS[res.result] or "successful",
        "theta": np.asarray(res.theta).tolist(),
        "singular_values": np.asarray(e.singular_values).tolist(),
        "excitation": float(res.stats["excitation"]),
        "residual_rms": float(res.stats["residual_rms"]),
        "estimator": estimator,
        "rho": rho,
        "note": "theta ordered as (3.8c): a1..an, mu_11..mu_n1, ..., mu_14..mu_n4; b "
        "normalised by (3.10) (sum b_i^2 = 1, first largest-magnitude entry > 0), "
        "points/k/h/l in that scale; d1, d2 signed (Fig. 2)",
    }


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
    from ...plotting.recursive_pl import plot_convergence, plot_fig3a, plot_fig3b

    summary, res, case = reproduce_section_vc(periods=args.periods)
    args.out.mkdir(parents=True, exist_ok=True)
    t = np.arange(res.history.shape[0])
    hist = recover_history(res)
    plot_fig3a(t, res.history, case.theta_star()).savefig(
        args.out / "fig3a.png", dpi=120
    )
    plot_fig3b(t, hist, case).savefig(args.out / "fig3b.png", dpi=120)
    plot_convergence(t, res.history, hist, case).savefig(
        args.out / "convergence.png", dpi=120
    )
    write_json(args.out / "reproduce.json", summary)
    print(f"wrote fig3a.png, fig3b.png, convergence.png, reproduce.json to {args.out}")
    for line in summary["headline"]:
        print(line)
    return 0


def samples_to_tolerance(errors: np.ndarray, tol: float) -> int | None:
    """Samples after which `errors[t] <= tol` for good (None if never)."""
    above = np.nonzero(np.asarray(errors) > tol)[0]
    if above.size == 0:
        return 0
    last = int(above[-1])
    return None if last == errors.shape[0] - 1 else last + 1


def reproduce_section_vc(*, periods: int = 2000):
    """Section V.C noise-free: Theta*, the gradient run and its convergence times.

    **Returns:** `(summary dict, RecursivePLResult, RecursivePLCase)`.
    """
    from ...internal.recursive_pl_plants import paper_case
    from ...simulation import simulate

    case = paper_case()
    _, v = pe_impulse_sequence(case.levels, order=2, periods=periods)
    y = simulate(case.plant(), v)
    res = identify_recursive_pl(v, y, levels=case.levels, order=2)
    theta_star = np.asarray(case.theta_star())
    printed = [0.56, -1.5, 1.66, -3.33, 1.33, -2.66, 1, -2, 1, -2]
    in_print_order = np.r_[theta_star[1], theta_star[0], theta_star[2:]]
    theta_err = np.abs(np.asarray(res.history) - theta_star).max(axis=1)
    hist = recover_history(res)
    truth = case.normalised_truth()
    phys = np.max(
        np.stack(
            [
                np.abs(np.asarray(getattr(hist, k)) - np.asarray(truth[k]))
                .reshape(theta_err.shape[0], -1)
                .max(axis=1)
                for k in ("a", "b", "d", "points", "k1", "k2", "h1", "h2")
            ]
        ),
        axis=0,
    )
    counts = {
        f"{name}_{tol:g}": samples_to_tolerance(err, tol)
        for name, err in (("theta", theta_err), ("physical", phys))
        for tol in (1e-3, 1e-6)
    }
    e = res.estimate
    # What each rule of (3.18) makes of the paper's (non-dead-zone, non-preload,
    # non-symmetric) map: the four points cannot identify D and L here.
    from ...identification.recursive_pl import recover_parameters

    rules = {}
    for s in STRUCTURES:
        r = recover_parameters(res.theta, levels=case.levels, order=2, structure=s)
        rules[s] = {k: float(getattr(r, k)) for k in ("d1", "d2", "l1", "l2")} | {
            "consistent": bool(r.consistent)
        }
    summary = {
        "plant": "A = 1 - 1.5 q^-1 + 0.56 q^-2, B = q^-1 - 2 q^-2, K = (1, 2), "
        "D = (1, -2), L = (1, -2), V = (-6, -3, 3, 6), z = 0",
        "theta_star": theta_star.tolist(),
        "theta_star_in_paper_print_order": in_print_order.tolist(),
        "theta_star_paper_print": printed,
        "max_abs_difference_to_print": float(np.max(np.abs(in_print_order - printed))),
        "samples": int(y.shape[0]),
        "samples_to_tolerance": counts,
        "final_theta_error": float(theta_err[-1]),
        "estimate": {
            "a": np.asarray(e.a).tolist(),
            "b": np.asarray(e.b).tolist(),
            "points": np.asarray(e.points).tolist(),
            "k1": float(e.k1),
            "k2": float(e.k2),
            "h1": float(e.h1),
            "h2": float(e.h2),
        },
        "truth_normalised_3_10": {k: np.asarray(x).tolist() for k, x in truth.items()},
        "rules_3_18_on_paper_map": rules,
    }
    summary["headline"] = [
        "theta* (paper print order a2, a1, mu..): "
        + " ".join(f"{x:.4g}" for x in in_print_order),
        f"samples to 1e-3 / 1e-6 (max |theta - theta*|): {counts['theta_0.001']} / "
        f"{counts['theta_1e-06']}; physical (a, b, F(Vj), K, H): "
        f"{counts['physical_0.001']} / {counts['physical_1e-06']}",
    ]
    return summary, res, case
