"""Argument helpers shared by the subcommands (the types live in `hamjax._argtypes`,
which the studies' own options use too)."""

import argparse
import importlib
from pathlib import Path
from types import ModuleType

from .._argtypes import (
    float_list as float_list,
    positive_float as positive_float,
    positive_int as positive_int,
)


def add_levels(p: argparse.ArgumentParser, *, help: str) -> None:
    """`--levels`: the input levels, comma-separated, required."""
    p.add_argument("--levels", type=float_list, required=True, help=help)


def add_sampling_period(p: argparse.ArgumentParser, *, help: str) -> None:
    """`--dt`: the sampling period, required."""
    p.add_argument("--dt", type=positive_float, required=True, help=help)


def add_init_duration(p: argparse.ArgumentParser, *, default: str) -> None:
    """`--init-duration`: T0 of the initialisation step (3), `default` said in the help."""
    p.add_argument(
        "--init-duration",
        type=positive_float,
        default=None,
        help=f"T0 of the initialisation step (3), seconds (default: {default})",
    )


def add_experiment_folder(p: argparse.ArgumentParser) -> None:
    """`--out`: the experiment folder an `experiment` command writes, required."""
    p.add_argument("--out", type=Path, required=True, help="experiment folder")


def add_data_folder(p: argparse.ArgumentParser) -> None:
    """`DIR`: the experiment folder an `identify` command reads data.csv from."""
    p.add_argument("dir", type=Path, help="experiment folder with data.csv")


def add_cluster_arguments(p: argparse.ArgumentParser, *, how: str) -> None:
    """`--coordinator`, `--num-processes`, `--process-id`, `--distributed`: several
    processes through `jax.distributed` (docs/cluster.md); `how` says what they share."""
    cluster = p.add_argument_group(
        "several processes (docs/cluster.md)",
        f"as jax.distributed.initialize: {how}",
    )
    detected = (
        "start jax.distributed with the cluster detected by JAX (SLURM, Open MPI, "
        "...) when --coordinator is not given"
    )
    for flag, options in (
        ("--coordinator", {"metavar": "HOST:PORT", "help": "address of process 0"}),
        (
            "--num-processes",
            {"type": positive_int, "metavar": "N", "help": "number of processes"},
        ),
        ("--process-id", {"type": int, "metavar": "I", "help": "this process, 0..N-1"}),
        ("--distributed", {"action": "store_true", "help": detected}),
    ):
        cluster.add_argument(flag, **options)


def start_cluster(args: argparse.Namespace) -> None:
    """`montecarlo.distributed.initialize` with the options of
    `add_cluster_arguments` (before any computation); a bad one is a user error."""
    from .._errors import UserInputError
    from ..montecarlo import distributed

    try:
        distributed.initialize(
            coordinator=getattr(args, "coordinator", None),
            num_processes=getattr(args, "num_processes", None),
            process_id=getattr(args, "process_id", None),
            auto=getattr(args, "distributed", False),
        )
    except ValueError as err:
        raise UserInputError(str(err)) from None


def optional_module(name: str) -> ModuleType | None:
    """`importlib.import_module(name)`, or None when `name` itself is not installed
    (an error inside the module, or a missing module it imports, still raises)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as err:
        if err.name == name:
            return None
        raise
