"""Helpers shared by the signal generators."""

import math

import jax.numpy as jnp
import numpy as np

from .._checks import check_finite, check_strictly_increasing, concrete


def samples_in(duration: float, dt: float, what: str) -> int:
    """Number of samples of period `dt` in `duration` seconds, which must be whole."""
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"sampling period dt must be finite and > 0; got {dt}")
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"{what} must be finite and > 0; got {duration}")
    n = round(duration / dt)
    if n < 1 or abs(n * dt - duration) > 1e-9 * max(1.0, duration):
        raise ValueError(
            f"{what} = {duration:g} s is not a whole number of samples of dt = {dt:g} s"
        )
    return n


def as_levels(levels, *, minimum: int, what: str = "levels") -> jnp.ndarray:
    """Validate strictly increasing finite levels, at least `minimum` of them.

    Traced levels (under `jit`/`vmap`) get the shape checks only."""
    if concrete(levels) is None:
        arr = jnp.asarray(levels, dtype=float)
        if arr.ndim != 1 or arr.shape[0] < minimum:
            raise ValueError(
                f"need a 1-D list of at least {minimum} {what}; got shape {arr.shape}"
            )
        return arr
    arr = np.asarray(levels, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{what} must be a 1-D list; got shape {arr.shape}")
    if arr.shape[0] < minimum:
        raise ValueError(f"need at least {minimum} {what}; got {arr.shape[0]}")
    check_finite(what, arr)
    check_strictly_increasing(what, arr)
    return jnp.asarray(arr)


def times(n: int, dt: float) -> jnp.ndarray:
    """Sample times $t_k = k\\,dt$, $k = 0..n-1$."""
    return jnp.arange(n, dtype=float) * dt
