"""`hamjax simulate MODEL_JSON --input input.csv --noise-std S --seed K --out data.csv`."""

import argparse
from pathlib import Path

import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import UserInputError


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a model.json plant on an input.csv")
    p.add_argument("model", type=Path, help="model.json (contracts/gap-case.md schema)")
    p.add_argument("--input", type=Path, required=True, help="CSV with columns t,v")
    p.add_argument(
        "--noise-std", type=float, default=0.0, help="white noise std (default 0)"
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--out", type=Path, required=True, help="output CSV (t,v,y)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import load_model, read_csv, sampling_period, write_csv
    from ..models import WhiteNoise, add_noise
    from ..simulation import simulate

    if not (np.isfinite(args.noise_std) and args.noise_std >= 0):
        raise UserInputError(
            f"--noise-std must be finite and >= 0; got {args.noise_std}"
        )
    plant, model_dt = load_model(args.model)
    data = read_csv(args.input, ("t", "v"))
    dt = sampling_period(data["t"])
    if model_dt is not None and abs(model_dt - dt) > 1e-9 * model_dt:
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
