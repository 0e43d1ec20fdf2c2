"""Seed 000 example: NBBI + FGI on G(s) = (s-10)/(s+1)^2 (Figs. 5, 6 and a Bode plot)."""

import argparse
from pathlib import Path

import jax.random as jr

from ...papers.seed000.fig6_example import run_example
from .._common import float_list, positive_float, positive_int


def add_reproduce_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="root random seed (default 0)")
    p.add_argument(
        "--noise", type=float, default=0.5, help="output noise std (default 0.5)"
    )
    p.add_argument(
        "--hold", type=positive_float, default=40.0, help="N*Tr seconds (default 40)"
    )
    p.add_argument(
        "--omega",
        type=float_list,
        default=[0.05, 0.2, 0.6, 2.0],
        help="comma-separated base frequencies (default 0.05,0.2,0.6,2)",
    )
    p.add_argument(
        "--periods", type=positive_int, default=40, help="M periods averaged (40)"
    )


def reproduce(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    args.out.mkdir(parents=True, exist_ok=True)
    summary, made = run_example(
        jr.key(args.seed),
        args.out,
        noise=args.noise,
        hold=args.hold,
        omegas=args.omega,
        periods=args.periods,
    )
    for name, what in made:
        print(f"  {name}: {what}")
    a = summary["nbbi"]
    print(
        f"NBBI max |error|: plain {a['max_abs_error_plain']:.3g}, settled "
        f"{a['max_abs_error_settled']:.3g}; FGI max |G-hat - G| "
        f"{summary['fgi']['max_abs_error']:.3g} over "
        f"{summary['fgi']['n_points']} points"
    )
    return 0
