"""General-purpose random excitations: random staircase, PRBS, random-phase multisine."""

import jax.numpy as jnp
import jax.random as jr
from jaxtyping import PRNGKeyArray

from .._types import Signal, Times
from ._common import times


def _check(n: int, dt: float) -> None:
    if int(n) != n or n < 1:
        raise ValueError(f"number of samples must be an integer >= 1; got {n}")
    if not dt > 0:
        raise ValueError(f"sampling period dt must be > 0; got {dt}")


def _check_hold(hold: int) -> None:
    if int(hold) != hold or hold < 1:
        raise ValueError(f"hold must be an integer >= 1 sample; got {hold}")


def random_staircase(
    key: PRNGKeyArray,
    *,
    n_samples: int,
    hold: int,
    low: float,
    high: float,
    dt: float = 1.0,
) -> tuple[Times, Signal]:
    """Levels drawn uniformly in $[\\text{low}, \\text{high}]$, each held `hold` samples."""
    _check(n_samples, dt)
    _check_hold(hold)
    if not low < high:
        raise ValueError(f"need low < high; got {low}, {high}")
    n_samples, hold = int(n_samples), int(hold)
    n_levels = -(-n_samples // hold)
    levels = jr.uniform(key, (n_levels,), minval=low, maxval=high)
    return times(n_samples, dt), jnp.repeat(levels, hold)[:n_samples]


def prbs(
    key: PRNGKeyArray,
    *,
    n_samples: int,
    hold: int = 1,
    amplitude: float = 1.0,
    dt: float = 1.0,
) -> tuple[Times, Signal]:
    """Random binary sequence $\\pm$`amplitude`, switching at most every `hold` samples."""
    _check(n_samples, dt)
    _check_hold(hold)
    n_samples, hold = int(n_samples), int(hold)
    n_levels = -(-n_samples // hold)
    bits = jr.bernoulli(key, 0.5, (n_levels,))
    v = jnp.where(bits, amplitude, -amplitude).astype(float)
    return times(n_samples, dt), jnp.repeat(v, hold)[:n_samples]


def multisine(
    key: PRNGKeyArray,
    *,
    n_samples: int,
    harmonics: int,
    rms: float = 1.0,
    dt: float = 1.0,
) -> tuple[Times, Signal]:
    """Random-phase multisine: harmonics $1..H$ of $2\\pi/(N\\,dt)$ with equal
    amplitudes and uniform random phases, scaled to the given `rms`. Periodic in
    `n_samples`.
    """
    _check(n_samples, dt)
    if not 1 <= harmonics < n_samples / 2:
        raise ValueError(
            f"harmonics must be in [1, n_samples/2); got {harmonics} for {n_samples}"
        )
    phases = jr.uniform(key, (harmonics,), maxval=2 * jnp.pi)
    k = jnp.arange(1, harmonics + 1, dtype=float)
    idx = jnp.arange(n_samples, dtype=float)
    v = jnp.sum(
        jnp.cos(2 * jnp.pi * k[:, None] * idx[None, :] / n_samples + phases[:, None]), 0
    )
    v = v * rms / jnp.sqrt(jnp.mean(v**2))
    return times(n_samples, dt), v
