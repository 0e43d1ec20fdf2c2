"""`hamjax simulate MODEL_JSON --input input.csv --noise-std S --seed K --out data.csv`."""

import argparse
from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import UserInputError


def register(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a model.json plant on an input.csv",
        description="Simulate the plant of MODEL (docs/model-json.md) from rest on the "
        "input v of --input and write t,v,y (y with white noise of --noise-std).",
    )
    p.add_argument("model", type=Path, help="model.json (docs/model-json.md)")
    p.add_argument("--input", type=Path, required=True, help="CSV with columns t,v")
    p.add_argument(
        "--noise-std", type=float, default=0.0, help="white noise std (default 0)"
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--out", type=Path, required=True, help="output CSV (t,v,y)")
    p.set_defaults(func=run)


def _check_out(args: argparse.Namespace) -> None:
    """--out is a writable file name, and neither input (before any work)."""
    from ._outputs import check_output_file, same_file

    check_output_file(args.out)
    for option, given in (("--input", args.input), ("MODEL", args.model)):
        if same_file(args.out, given):
            raise UserInputError(f"{args.out}: --out is the {option} file")


def run(args: argparse.Namespace) -> int:
    from ..io import load_model, read_csv, require_stable, sampling_period, write_csv
    from ..models import WhiteNoise, add_noise
    from ..simulation import simulate

    if not (np.isfinite(args.noise_std) and args.noise_std >= 0):
        raise UserInputError(
            f"--noise-std must be finite and >= 0; got {args.noise_std}"
        )
    _check_out(args)
    plant, model_dt = load_model(args.model)
    require_stable(plant, args.model)
    data = read_csv(args.input, ("t", "v"))
    dt = sampling_period(data["t"])
    if model_dt is not None and abs(model_dt - dt) > 1e-6 * model_dt:
        raise UserInputError(
            f"{args.input}: sampled at dt = {dt:g} s but {args.model} has dt = {model_dt:g} s"
        )
    try:
        w = simulate(plant, jnp.asarray(data["v"]), dt=dt)
    except ValueError as err:
        raise UserInputError(f"{args.model}: {err}") from None
    y = add_noise(jr.key(args.seed), w, WhiteNoise(args.noise_std))
    write_csv(args.out, {"t": data["t"], "v": data["v"], "y": np.asarray(y)})
    print(f"wrote {args.out} ({len(y)} samples)")
    return 0
