"""A start for the seed-000 refinement from NBBI's border points alone.

NBBI (seed 000, Table 1) gives the cycle values $U_i$ but no $G$. With $u$ then
known, the output-error cost of an all-pole $G(s) = \\omega_0^p/(s + \\omega_0)^p$
is evaluated on a grid of $\\omega_0$ and the best one starts the joint fit.
"""

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._types import Params, Signal
from .backlash_path import BacklashPathParametrisation


def first_hold_value(parametrisation: BacklashPathParametrisation, y: Signal):
    """Mean of `y` over the second half of the first hold (the nuisance $u_0$)."""
    first = parametrisation.positions == 0
    count = jnp.sum(first)
    index = jnp.cumsum(first)
    late = first & (index > count // 2)
    return jnp.sum(jnp.where(late, y, 0.0)) / jnp.maximum(jnp.sum(late), 1)


def initial_backlash_theta(
    parametrisation: BacklashPathParametrisation,
    cycle_values: Float[Array, " m"],
    v: Signal,
    y: Signal,
    *,
    omegas: Float[Array, " grid"] | None = None,
) -> Params:
    """$\\theta_0$ = (NBBI's $U_i$, the best all-pole $G$ of the grid, zero
    numerator coefficients, $u_0$ from the first hold).

    `omegas` (rad/s) defaults to 40 values log-spaced from $2\\pi/(\\text{record})$
    to $1/(2\\,dt)$.
    """
    p, m = parametrisation.den_order, parametrisation.num_order
    if omegas is None:
        record = v.shape[0] * parametrisation.dt
        omegas = jnp.logspace(
            math.log10(2 * math.pi / record), math.log10(0.5 / parametrisation.dt), 40
        )
    u0 = first_hold_value(parametrisation, y)
    binom = jnp.asarray([math.comb(p, k) for k in range(1, p + 1)], dtype=float)
    powers = jnp.arange(1, p + 1, dtype=float)

    def theta_for(omega):
        alpha = binom * omega**powers  # (s + omega)^p
        return jnp.concatenate([cycle_values, alpha, jnp.zeros(m), u0[None]])

    def cost(omega):
        r = y - parametrisation.predict(theta_for(omega), v)
        return jnp.sum(jnp.where(jnp.isfinite(r), r, 1e150) ** 2)

    costs = jax.vmap(cost)(omegas)
    return theta_for(omegas[jnp.argmin(costs)])
