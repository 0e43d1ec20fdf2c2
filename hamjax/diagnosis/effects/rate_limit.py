"""`rate_limit`: $v'$ follows $v$ with $|dv'/dt| \\le r$ (input units per second)."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext


def rate_limit_step(
    x_prev: Float[Array, ""], v: Float[Array, ""], max_step: Float[Array, ""]
) -> Float[Array, ""]:
    """$x_k = x_{k-1} + \\mathrm{clip}(v_k - x_{k-1}, -r\\,dt, r\\,dt)$, from $x_{-1} = v_0$.

    Written as $\\mathrm{clip}(v_k, x_{k-1} - r\\,dt, x_{k-1} + r\\,dt)$ so that the
    neutral $r = \\infty$ returns $v_k$ exactly (no rounding of $x + (v - x)$).
    """
    return jnp.clip(v, x_prev - max_step, x_prev + max_step)


class RateLimitEffect(AbstractEffect):
    """Slew-rate limit $r > 0$ (neutral $r = \\infty$)."""

    name = "rate_limit"
    slots = ("rate",)
    neutral = {"rate": np.inf}
    positive = ("rate",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"rate": 0.1 * ctx.max_step / ctx.dt}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        r = ctx.max_step / ctx.dt
        return [{"rate": 0.3 * r}, {"rate": 0.05 * r}]
