"""`saturation`: $u' = \\mathrm{clip}(F(v), u_{lo}, u_{hi})$ between $F$ and $G$."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext, quantile_pair


def saturate(
    u: Float[Array, "*shape"], lower: Float[Array, ""], upper: Float[Array, ""]
) -> Float[Array, "*shape"]:
    """$\\mathrm{clip}(u, u_{lo}, u_{hi})$; neutral at $\\mp\\infty$.

    >>> saturate(jnp.array([-3.0, 0.0, 3.0]), -1.0, 2.0)  # [-1, 0, 2]
    """
    return jnp.clip(u, lower, upper)


class SaturationEffect(AbstractEffect):
    """Two-sided clipping of the nominal $u$ (neutral $u_{lo} = -\\infty$, $u_{hi} = \\infty$)."""

    name = "saturation"
    slots = ("sat_lo", "sat_hi")
    neutral = {"sat_lo": -np.inf, "sat_hi": np.inf}

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"sat_lo": 0.2 * ctx.u_std, "sat_hi": 0.2 * ctx.u_std}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        """Limits at nominal-u quantiles: both light, both heavy, and one side
        only (the other limit at the 2 % / 98 % quantile, where it still bites and
        keeps its gradient). A limit started far inside the range it truly clips
        little of has to walk out while the re-fitted map and poles compensate it;
        on a slow plant that fit stalled (blind seed 301, case 137)."""
        out = []
        for lo, hi in ((0.1, 0.9), (0.3, 0.7), (0.1, 0.98), (0.02, 0.9)):
            a, b = quantile_pair(ctx, lo, hi)
            out.append({"sat_lo": a, "sat_hi": b})
        return out
