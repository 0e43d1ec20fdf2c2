"""`backlash`: a play operator of total width $c$ on $v$ before $F$."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext, scale_span, span


def play_step(
    x_prev: Float[Array, ""], v: Float[Array, ""], width: Float[Array, ""]
) -> Float[Array, ""]:
    """One step of the play operator $x_k = \\min(\\max(x_{k-1}, v_k - c/2), v_k + c/2)$.

    Started at $x_{-1} = v_0$ (centred in the play), this equals
    `hj.Backlash.from_width(c, u0=v[0])`; with $c = 0$ it returns $v_k$ exactly.
    """
    return jnp.clip(x_prev, v - width / 2, v + width / 2)


class BacklashEffect(AbstractEffect):
    """Play of width $c \\ge 0$ (neutral $c = 0$)."""

    name = "backlash"
    slots = ("backlash",)
    neutral = {"backlash": 0.0}
    positive = ("backlash",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"backlash": 0.05 * scale_span(ctx)}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{"backlash": 0.04 * span(ctx)}, {"backlash": 0.2 * span(ctx)}]
