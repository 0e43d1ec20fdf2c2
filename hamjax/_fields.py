"""Fields shared by the modules: given as anything array-like, stored as float arrays."""

import equinox as eqx
import jax.numpy as jnp


def as_float(x):
    """`x` as a float array (float64: hamjax enables x64)."""
    return jnp.asarray(x, dtype=float)


def float_field(**kwargs):
    """An `eqx.field` converted by `as_float` when the module is built; `kwargs` as
    for `eqx.field` (`kw_only=True`, `default=...`)."""
    return eqx.field(converter=as_float, **kwargs)
