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


def optional_module(name: str) -> ModuleType | None:
    """`importlib.import_module(name)`, or None when `name` itself is not installed
    (an error inside the module, or a missing module it imports, still raises)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as err:
        if err.name == name:
            return None
        raise
