"""Argument helpers shared by the subcommands (the types live in `hamjax._argtypes`,
which the studies' own options use too)."""

from .._argtypes import (
    float_list as float_list,
    positive_float as positive_float,
    positive_int as positive_int,
)
