"""`preload`: $u' = F(v) + c\\,\\mathrm{sign}(v)$ (a Coulomb-like jump at $v = 0$)."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext


def add_preload(
    u: Float[Array, "*shape"], v: Float[Array, "*shape"], c: Float[Array, ""]
) -> Float[Array, "*shape"]:
    """$u + c\\,\\mathrm{sign}(v)$ with $\\mathrm{sign}(0) = 0$; neutral $c = 0$."""
    return u + c * jnp.sign(v)


class PreloadEffect(AbstractEffect):
    """Jump of height $c$ at $v = 0$."""

    name = "preload"
    slots = ("preload",)
    neutral = {"preload": 0.0}

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"preload": 0.1 * ctx.u_std}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{"preload": 0.1 * ctx.u_std}]
