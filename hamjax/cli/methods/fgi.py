"""FGI (seed 000, Table 2): periodic staircase experiment and G(jk omega)."""

import argparse
import dataclasses
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..._errors import UserInputError
from ..._results import RESULTS
from ...identification.seed000.fgi_table2 import identify_fgi
from ...io import read_data, read_design, read_json, write_csv, write_json
from ...signals import FGIDesign
from .._common import (
    add_data_folder,
    add_experiment_folder,
    add_init_duration,
    add_sampling_period,
    positive_float,
    positive_int,
)
from .._methods import result_path
from .nbbi import check_levels, design_start


DISCRETISATION = (
    "u is reconstructed exactly (piecewise constant on whole samples); (22) integrates "
    "y_f held over each sample (ZOH convention): relative error about k*omega*dt/2 in "
    "phase and (k*omega*dt)^2/24 in gain; 'rectangle' leaves only aliasing"
)


def add_experiment_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--nbbi", type=Path, required=True, help="finished nbbi folder")
    p.add_argument(
        "--omega",
        type=positive_float,
        action="append",
        required=True,
        help="fundamental frequency (rad/s); repeat for several (Remark 2a)",
    )
    p.add_argument(
        "--periods", type=positive_int, required=True, help="M periods averaged (20)"
    )
    add_sampling_period(p, help="sampling period (s)")
    p.add_argument(
        "--transient-periods",
        type=int,
        default=None,
        help="periods discarded before the M averaged ones (default: enough to cover "
        "the NBBI hold time N*Tr, which was chosen long enough to settle)",
    )
    add_init_duration(p, default="the NBBI one")
    add_experiment_folder(p)


def experiment(args: argparse.Namespace) -> int:
    nbbi_dir: Path = args.nbbi
    nbbi_design = read_design(nbbi_dir, "nbbi")
    res_path = nbbi_dir / "result.json"
    if not res_path.is_file():
        raise UserInputError(f"{res_path}: file not found (run `hamjax identify nbbi`)")
    nbbi = read_json(res_path)
    levels = check_levels(nbbi_design["levels"], str(nbbi_dir / "experiment.json"))
    m = 2 * len(levels) - 2
    cycle = np.asarray(nbbi.get("cycle", []), dtype=float)
    if cycle.shape != (m, 2) or not np.all(np.isfinite(cycle)):
        raise UserInputError(f"{res_path}: 'cycle' must hold {m} finite [V, U] points")
    stderr = nbbi.get("uncertainty", nbbi.get("stderr"))
    dt = float(args.dt)
    if args.transient_periods is not None and args.transient_periods < 0:
        raise UserInputError("--transient-periods must be >= 0")
    init = args.init_duration or float(
        nbbi_design.get("init_duration", nbbi_design["hold"])
    )
    settle = float(nbbi_design["hold"])
    if abs(init / dt - round(init / dt)) > 1e-9 * max(1.0, init / dt):
        raise UserInputError(
            f"--init-duration {init:g} s (default: the NBBI one) is not a whole number "
            f"of samples of --dt {dt:g}"
        )
    blocks, start = [], int(round(init / dt)) * 2
    for omega in args.omega:
        try:
            fgi = FGIDesign.settling(
                levels, omega=omega, dt=dt, periods=args.periods, settle=settle
            )
        except ValueError as err:
            raise UserInputError(f"--omega {omega:g}: {err}") from None
        if args.transient_periods is not None:
            fgi = dataclasses.replace(fgi, transient_periods=args.transient_periods)
        blocks.append(
            {
                "omega_requested": omega,
                "omega": fgi.omega,
                "period_samples": fgi.period_samples,
                "transient_periods": fgi.transient_periods,
                "periods": fgi.periods,
                "start": start,
                "average_start": fgi.start(start),
            }
        )
        start += fgi.total_periods * fgi.period_samples
    design = {
        "method": "fgi",
        "dt": dt,
        "levels": levels,
        "cycle_levels": cycle[:, 0].tolist(),
        "cycle_values": cycle[:, 1].tolist(),
        "cycle_stderr": stderr,
        "nbbi": str(nbbi_dir),
        "init_duration": init,
        "periods": args.periods,
        "omega": [b["omega"] for b in blocks],
        "blocks": blocks,
        "n_samples": start,
        "note": "input.csv = initialisation (3), then for each omega the periodic "
        "staircase (24) for transient_periods + periods periods; the system must "
        "start at rest",
    }
    t, v = fgi_input(design)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "experiment.json", design)
    write_csv(args.out / "input.csv", {"t": t, "v": v})
    used = ", ".join(f"{b['omega']:.6g}" for b in blocks)
    print(
        f"wrote {args.out / 'experiment.json'} and input.csv ({t.shape[0]} samples); "
        f"omega used: {used} rad/s"
    )
    return 0


def fgi_input(design: dict) -> tuple[np.ndarray, np.ndarray]:
    """The designed input: initialisation (3), then (24) for each omega block."""
    try:
        levels, dt, v0 = design_start(design)
        parts = [np.asarray(v0)]
        for b in design["blocks"]:
            fgi = FGIDesign(
                tuple(float(x) for x in levels),
                dt,
                float(b["omega"]),
                int(b["period_samples"]),
                int(b["transient_periods"]),
                int(b["periods"]),
            )
            parts.append(np.asarray(fgi.input()[1]))
    except (ValueError, KeyError, TypeError) as err:
        raise UserInputError(f"experiment.json: invalid FGI design ({err})") from None
    v = np.concatenate(parts)
    return np.arange(v.shape[0]) * dt, v


def add_identify_arguments(p: argparse.ArgumentParser) -> None:
    add_data_folder(p)
    p.add_argument(
        "--epsilon",
        type=float,
        default=0.05,
        help="Remark 2b: keep harmonics up to the power fraction 1 - epsilon (0.05)",
    )
    p.add_argument(
        "--max-harmonic", type=positive_int, default=64, help="largest k considered"
    )
    p.add_argument(
        "--quadrature",
        choices=("hold", "rectangle"),
        default="rectangle",
        help="integration of (22) from the samples of y: rectangle (periodic "
        "rectangle rule, aliasing error only; default) or hold (y held over each "
        "sample, relative error about k*omega*dt/2)",
    )
    p.add_argument(
        "--refine",
        action="store_true",
        help="add a joint output-error fit of G(jk omega) at the kept harmonics and "
        "the border points U_i to the NBBI and FGI records (optimistix), with "
        "standard errors, under 'refined'",
    )
    p.add_argument(
        "--nbbi",
        type=Path,
        default=None,
        help="the nbbi folder whose data.csv enters the refinement (--refine; "
        "default: the one recorded in experiment.json)",
    )
    p.add_argument(
        "--settle",
        type=float,
        default=None,
        help="seconds of each NBBI hold left out of the refinement as transient "
        "(--refine; default: half the hold)",
    )


def identify(args: argparse.Namespace) -> int:
    out = result_path(args)
    folder: Path = args.dir
    if not 0 < args.epsilon < 1:
        raise UserInputError(f"--epsilon must be in (0, 1); got {args.epsilon}")
    design = read_design(folder, "fgi")
    _, v = fgi_input(design)
    y = read_data(folder, design, v)
    stderr = design.get("cycle_stderr")
    entries, summaries = [], []
    for b in design["blocks"]:
        res = identify_fgi(
            y,
            design["cycle_values"],
            period_samples=int(b["period_samples"]),
            periods=int(b["periods"]),
            dt=float(design["dt"]),
            start=int(b["average_start"]),
            epsilon=args.epsilon,
            max_harmonic=args.max_harmonic,
            cycle_stderr=None if stderr is None else jnp.asarray(stderr, dtype=float),
            quadrature=args.quadrature,
            throw=False,
        )
        if res.result == RESULTS.cycle_not_rebuilt:
            raise UserInputError(f"omega = {b['omega']:g}: {RESULTS[res.result]}")
        if res.result != RESULTS.successful:
            raise UserInputError(
                f"{folder / 'data.csv'}: omega = {b['omega']:g}: no usable harmonic "
                "(the NBBI cycle is flat or the output is not finite)"
            )
        fr = res.frequency_response()
        entries.extend(fr)
        summaries.append(
            {
                "omega": float(res.omega),
                "parseval_order": int(res.order),
                "kept": [e["k"] for e in fr],
            }
        )
    result = {
        "method": "fgi",
        "frequency_response": entries,
        "omega": [s["omega"] for s in summaries],
        "harmonics": summaries,
        "epsilon": args.epsilon,
        "quadrature": args.quadrature,
        "discretisation": DISCRETISATION,
    }
    write_json(out, result)
    print(f"wrote {out}: {len(entries)} frequency-response points")
    if args.refine:
        result.update(_refine(args, design, y, result))
        write_json(out, result)
        state = "converged" if result["converged"] else "did NOT converge"
        print(f"refinement {state}; added 'refined' and 'standard_errors'")
    return 0


def _refine(args: argparse.Namespace, design: dict, y: np.ndarray, result: dict):
    """The `--refine` part of `identify`: both records in one likelihood."""
    from ...refinement import refine_fgi_result
    from .nbbi import nbbi_input

    nbbi_dir = args.nbbi if args.nbbi is not None else design.get("nbbi")
    if nbbi_dir is None:
        raise UserInputError(
            "--refine needs the NBBI record: pass --nbbi DIR (a finished nbbi folder "
            "with data.csv)"
        )
    nbbi_dir = Path(nbbi_dir)
    nbbi_design = read_design(nbbi_dir, "nbbi")
    levels = check_levels(nbbi_design["levels"], str(nbbi_dir / "experiment.json"))
    if not np.allclose(levels, design["levels"], rtol=0, atol=1e-12):
        raise UserInputError(
            f"{nbbi_dir / 'experiment.json'}: levels {levels} differ from the FGI "
            f"design's {design['levels']}"
        )
    _, v_nbbi = nbbi_input(nbbi_design)
    y_nbbi = read_data(nbbi_dir, nbbi_design, v_nbbi)
    dt_nbbi, hold = float(nbbi_design["dt"]), float(nbbi_design["hold"])
    hold_samples = int(round(hold / dt_nbbi))
    settle = hold / 2 if args.settle is None else float(args.settle)
    if not (math.isfinite(settle) and 0 <= settle < hold):
        raise UserInputError(f"--settle must be in [0, hold = {hold:g}); got {settle}")
    settle_samples = int(round(settle / dt_nbbi))
    try:
        refined = refine_fgi_result(
            y_nbbi,
            y,
            result,
            levels=levels,
            cycle_values=design["cycle_values"],
            nbbi_start=int(nbbi_design["init_samples"]),
            hold_samples=hold_samples,
            settle_samples=settle_samples,
            blocks=design["blocks"],
            dt=float(design["dt"]),
        )
    except ValueError as err:
        raise UserInputError(f"--refine: {err}") from None
    refined["nbbi"] = str(nbbi_dir)
    refined["settle"] = settle_samples * dt_nbbi
    refined["refinement_note"] = (
        "joint output-error fit of the settled NBBI holds (G(0) U_i) and the FGI "
        "averaged periods (steady state at the kept harmonics), G(0) = 1 eliminated; "
        "standard errors from the Fisher information with the noise std estimated "
        "from the replicates (holds, periods)"
    )
    return refined
