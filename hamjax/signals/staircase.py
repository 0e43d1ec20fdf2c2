"""Seed 000's experiment inputs: initialisation step (3), staircase (4a-b),
periodic staircase (24).

Brouri, Giri, Rochdi, Chaoui, *Frequency identification of nonparametric
Hammerstein systems with backlash nonlinearity*, Tables 1 and 2.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._types import Signal, Times
from ._common import as_levels, samples_in, times


def staircase_cycle_levels(levels: Float[Array, " n"]) -> Float[Array, " m"]:
    """The 2n-2 levels of (4a-b) in staircase order: $V_1 \\dots V_n, V_{n-1} \\dots V_2$."""
    levels = as_levels(levels, minimum=3)
    return jnp.concatenate([levels, levels[-2:0:-1]])


def initialisation_step(
    levels: Float[Array, " n"], *, duration: float, dt: float
) -> tuple[Times, Signal]:
    """Eq. (3): $v = v_M$ on $[0, T_0)$ then $v = v_m$ on $[T_0, 2T_0)$.

    Leaves the backlash working point at $(v_m, f_d(v_m))$ (position 1 of Fig. 5).
    `duration` is $T_0$ in seconds.
    """
    levels = as_levels(levels, minimum=2)
    n0 = samples_in(duration, dt, "initialisation duration T0")
    v = jnp.concatenate([jnp.full(n0, levels[-1]), jnp.full(n0, levels[0])])
    return times(2 * n0, dt), v


def nbbi_staircase(
    levels: Float[Array, " n"], *, hold: float, dt: float
) -> tuple[Times, Signal]:
    """Eq. (4a-b): each of the 2n-2 cycle levels held for `hold` $= N T_r$ seconds.

    **Returns:** `(t, v)`, $(2n-2) \\cdot$ `hold`/`dt` samples from $t = 0$.
    """
    cycle = staircase_cycle_levels(levels)
    per_level = samples_in(hold, dt, "hold N*Tr")
    v = jnp.repeat(cycle, per_level)
    return times(v.shape[0], dt), v


def periodic_staircase(
    levels: Float[Array, " n"], *, period_samples: int, periods: int, dt: float
) -> tuple[Times, Signal]:
    """Eq. (24): the cycle levels, each held $\\tau = T/(2n-2)$, repeated `periods` times.

    `period_samples` (the period $T$ in samples) must be a multiple of $2n-2$ so
    that $\\tau$ is a whole number of samples; see `fgi_period_samples`.
    """
    cycle = staircase_cycle_levels(levels)
    m = cycle.shape[0]
    if int(period_samples) != period_samples or int(periods) != periods:
        raise ValueError(
            f"period_samples and periods must be integers; got {period_samples}, "
            f"{periods}"
        )
    period_samples, periods = int(period_samples), int(periods)
    if period_samples <= 0 or period_samples % m:
        raise ValueError(
            f"period of {period_samples} samples must be a positive multiple of "
            f"2n-2 = {m}"
        )
    if periods < 1:
        raise ValueError(f"periods must be >= 1; got {periods}")
    one = jnp.repeat(cycle, period_samples // m)
    v = jnp.tile(one, periods)
    return times(v.shape[0], dt), v


def fgi_period_samples(omega: float, dt: float, n_levels: int) -> tuple[int, float]:
    """Round $T = 2\\pi/\\omega$ to a whole number of samples, a multiple of $2n-2$.

    **Returns:** `(period_samples, omega_used)` with
    `omega_used = 2 pi / (period_samples * dt)`.

    **Raises:** `ValueError` if $\\omega \\le 0$ or the period would hold fewer than
    $2n-2$ samples.
    """
    import math

    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be finite and > 0; got {omega}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"sampling period dt must be > 0; got {dt}")
    if int(n_levels) != n_levels or n_levels < 2:
        raise ValueError(f"n_levels must be an integer >= 2; got {n_levels}")
    m = 2 * int(n_levels) - 2
    per = 2 * math.pi / (omega * dt)
    k = round(per / m)
    if k < 1:
        raise ValueError(
            f"omega = {omega:g} rad/s is too high for dt = {dt:g} s: the period holds "
            f"{per:.3g} samples, fewer than 2n-2 = {m}"
        )
    period_samples = k * m
    return period_samples, 2 * math.pi / (period_samples * dt)
