"""`time_delay`: $v'(t) = v(t - \\tau)$, $\\tau$ a whole number of samples."""

import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._base import AbstractEffect


MAX_DELAY = 8  # samples tried (one vmapped row each); the neutral delay is 0


def delay(v: Float[Array, " time"], tau: Int[Array, ""]) -> Float[Array, " time"]:
    """$v_{k-\\tau}$, holding $v_0$ before $t = 0$ (the contract); $\\tau = 0$ is neutral."""
    idx = jnp.maximum(jnp.arange(v.shape[0]) - tau, 0)
    return jnp.asarray(v)[idx]


class TimeDelayEffect(AbstractEffect):
    """Integer delay, fitted by trying $\\tau = 1..$`MAX_DELAY` (a fractional delay is
    named `time_delay` through its nearest whole-sample fit)."""

    name = "time_delay"
