"""NBBI (seed 000, Table 1): staircase experiment and backlash border points."""

import argparse
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..._errors import UserInputError
from ...identification.seed000.nbbi_table1 import identify_nbbi, narrow_message
from ...io import read_data, read_design, write_csv, write_json
from ...signals import initialisation_step, nbbi_staircase
from .._common import (
    add_data_folder,
    add_experiment_folder,
    add_init_duration,
    add_levels,
    add_sampling_period,
    positive_float,
)
from .._methods import result_path


# ----------------------------------------------------------------------------- design


def add_experiment_arguments(p: argparse.ArgumentParser) -> None:
    add_levels(
        p, help="V1,...,Vn strictly increasing, n >= 3 (e.g. --levels=-1,-0.5,0,0.5,1)"
    )
    p.add_argument(
        "--hold", type=positive_float, required=True, help="seconds per level (N*Tr)"
    )
    add_sampling_period(p, help="sampling period (s)")
    add_init_duration(p, default="--hold")
    add_experiment_folder(p)


def experiment(args: argparse.Namespace) -> int:
    levels = check_levels(args.levels, "--levels")
    init = args.hold if args.init_duration is None else args.init_duration
    design = {
        "method": "nbbi",
        "dt": args.dt,
        "levels": levels,
        "hold": args.hold,
        "init_duration": init,
    }
    t, v = nbbi_input(design)
    design["init_samples"] = int(
        initialisation_step(levels, duration=init, dt=args.dt)[0].shape[0]
    )
    design["hold_samples"] = int(round(args.hold / args.dt))
    design["n_samples"] = int(t.shape[0])
    design["note"] = (
        "input.csv = initialisation step (3) (v_M then v_m, init_duration each) followed "
        "by the staircase (4a-b); the system must start at rest"
    )
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "experiment.json", design)
    write_csv(args.out / "input.csv", {"t": t, "v": v})
    print(f"wrote {args.out / 'experiment.json'} and input.csv ({t.shape[0]} samples)")
    return 0


def check_levels(levels, what: str) -> list[float]:
    """Strictly increasing, at least 3 (Table 1)."""
    levels = [float(x) for x in levels]
    if len(levels) < 3:
        raise UserInputError(f"{what}: NBBI needs n >= 3 levels; got {len(levels)}")
    for i in range(len(levels) - 1):
        if not levels[i] < levels[i + 1]:
            raise UserInputError(
                f"{what}: levels must be strictly increasing; got {levels[i]:g} then "
                f"{levels[i + 1]:g}"
            )
    return levels


def design_start(design: dict) -> tuple[jnp.ndarray, float, jnp.ndarray]:
    """`(levels, dt, v0)` of a staircase design (NBBI's or FGI's): its levels, its
    sampling period and its initialisation step (3) of `init_duration` seconds."""
    levels = jnp.asarray(design["levels"], dtype=float)
    dt = float(design["dt"])
    _, v0 = initialisation_step(levels, duration=float(design["init_duration"]), dt=dt)
    return levels, dt, v0


def nbbi_input(design: dict) -> tuple[np.ndarray, np.ndarray]:
    """The designed input: initialisation (3) then staircase (4a-b)."""
    try:
        levels, dt, v0 = design_start(design)
        _, v1 = nbbi_staircase(levels, hold=float(design["hold"]), dt=dt)
    except ValueError as err:
        raise UserInputError(str(err)) from None
    v = np.concatenate([np.asarray(v0), np.asarray(v1)])
    return np.arange(v.shape[0]) * dt, v


# ----------------------------------------------------------------------------- identify


def add_identify_arguments(p: argparse.ArgumentParser) -> None:
    add_data_folder(p)
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--discard",
        type=float,
        default=0.0,
        help="seconds discarded at the start of each interval before averaging "
        "(default 0: the plain average (5))",
    )
    g.add_argument(
        "--settled",
        action="store_true",
        help="average only the second half of each interval (discards the transient)",
    )
    p.add_argument(
        "--refine",
        action="store_true",
        help="add a joint output-error fit of the border points and a parametric "
        "G(s) (optimistix), with standard errors, under 'refined'",
    )
    p.add_argument(
        "--den-order",
        type=int,
        default=2,
        help="order of G(s)'s denominator (--refine)",
    )
    p.add_argument(
        "--num-order", type=int, default=1, help="order of G(s)'s numerator (--refine)"
    )


def identify(args: argparse.Namespace) -> int:
    out = result_path(args)
    folder: Path = args.dir
    design = read_design(folder, "nbbi")
    _, v = nbbi_input(design)
    y = read_data(folder, design, v)
    dt, hold = float(design["dt"]), float(design["hold"])
    per_level = int(round(hold / dt))
    if args.settled:
        discard = (per_level // 2) * dt
    else:
        discard = float(args.discard)
        if not (math.isfinite(discard) and 0 <= discard < hold):
            raise UserInputError(
                f"--discard must be in [0, hold = {hold:g}); got {discard}"
            )
        discard = round(discard / dt) * dt
    res = identify_nbbi(
        y,
        design["levels"],
        hold=hold,
        dt=dt,
        start=int(design["init_samples"]),
        discard=discard,
        throw=False,
    )
    if not _ok(res):
        raise UserInputError(f"{folder / 'data.csv'}: {narrow_message(res)}")
    result = {
        "method": "nbbi",
        "ascending": np.asarray(res.ascending).tolist(),
        "descending": np.asarray(res.descending).tolist(),
        "cycle": np.asarray(res.cycle).tolist(),
        "stderr": np.asarray(res.stderr).tolist(),
        "uncertainty": np.asarray(res.uncertainty).tolist(),
        "noise_std": float(res.noise_std),
        "average": "plain (5)"
        if discard == 0
        else f"settled (first {discard:g} s dropped)",
        "discard": discard,
        "note": "U values in output units (G(0) = 1), cycle order of (4a-b); stderr "
        "assumes white noise; uncertainty adds the transient bias estimate",
    }
    write_json(out, result)
    print(f"wrote {out}: {2 * len(design['levels']) - 2} cycle points")
    if args.refine:
        if not 1 <= args.den_order or not 0 <= args.num_order <= args.den_order:
            raise UserInputError(
                "--den-order must be >= 1 and 0 <= --num-order <= --den-order; got "
                f"{args.den_order}, {args.num_order}"
            )
        from ...refinement import refine_nbbi_result

        refined = refine_nbbi_result(
            v,
            y,
            result,
            levels=design["levels"],
            dt=dt,
            den_order=args.den_order,
            num_order=args.num_order,
        )
        result.update(refined)
        write_json(out, result)
        state = "converged" if refined["converged"] else "did NOT converge"
        print(f"refinement {state}; added 'refined' and 'standard_errors'")
    return 0


def _ok(res) -> bool:
    from ..._results import RESULTS

    return bool(res.result == RESULTS.successful)
