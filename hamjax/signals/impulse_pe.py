"""Seed 001's persistently exciting impulse sequence (5.1).

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*, Section V.A.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._types import Signal, Times
from ._common import as_levels, times


def pe_impulse_sequence(
    levels: Float[Array, " 4"], *, order: int, periods: int, dt: float = 1.0
) -> tuple[Times, Signal]:
    """Eq. (5.1): period $T = 7n$; within period $k$ (from $t_k = kT$),
    $v(t_k + 2n) = V_1$, $v(t_k + (2 + j)n) = V_j$ for $j = 2, 3, 4$, else $0$.

    **Arguments:**

    - `levels`: $(V_1, V_2, V_3, V_4)$, strictly increasing.
    - `order`: $n$, the order of $A$ and $B$ ($n \\ge 1$).
    - `periods`: number of periods.
    - `dt`: sampling period (s) for the returned times.

    **Returns:** `(t, v)` with `7 * order * periods` samples.
    """
    levels = as_levels(levels, minimum=4)
    if levels.shape[0] != 4:
        raise ValueError(f"(5.1) needs exactly 4 levels V1..V4; got {levels.shape[0]}")
    if int(order) != order or order < 1:
        raise ValueError(f"order n must be an integer >= 1; got {order}")
    if int(periods) != periods or periods < 1:
        raise ValueError(f"periods must be an integer >= 1; got {periods}")
    n = int(order)
    one = jnp.zeros(7 * n)
    one = one.at[2 * n].set(levels[0])
    for j in (2, 3, 4):
        one = one.at[(2 + j) * n].set(levels[j - 1])
    v = jnp.tile(one, int(periods))
    return times(v.shape[0], dt), v
