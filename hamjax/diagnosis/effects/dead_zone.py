"""`dead_zone`: $v' = v - \\mathrm{clip}(v, -w_-, w_+)$ before $F$."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext


def dead_zone(
    v: Float[Array, "*shape"], lower: Float[Array, ""], upper: Float[Array, ""]
) -> Float[Array, "*shape"]:
    """Dead band $[-w_-, w_+]$; symmetric $w_\\pm = w$ is $\\mathrm{sign}(v)\\max(|v|-w, 0)$.

    >>> dead_zone(jnp.array([-2.0, -0.5, 0.5, 2.0]), 1.0, 1.0)  # [-1, 0, 0, 1]
    """
    return v - jnp.clip(v, -lower, upper)


class DeadZoneEffect(AbstractEffect):
    """Asymmetric dead band (widths $w_-, w_+ \\ge 0$, neutral 0).

    In front of a piecewise-linear map it is exactly a shift of $d_1, d_2$, so the
    diagnosis then counts it as `parameter_mismatch` (the contract).
    """

    name = "dead_zone"
    slots = ("dz_lo", "dz_hi")
    neutral = {"dz_lo": 0.0, "dz_hi": 0.0}
    positive = ("dz_lo", "dz_hi")

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"dz_lo": 0.05 * ctx.v_absmax, "dz_hi": 0.05 * ctx.v_absmax}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        a = ctx.v_absmax
        return [
            {"dz_lo": 0.05 * a, "dz_hi": 0.05 * a},
            {"dz_lo": 0.3 * a, "dz_hi": 0.3 * a},
        ]
