r"""`feedback_nonlinearity`: $u' = F(v) - \phi(w)$, $\phi$ static and not affine, fed
back from the output to the input of $G$.

Two shapes (two starts, each freeing its own slots):

- cubic stiffness $\phi = k_3\,(w/H)^3\,U$ (`fb_cubic`, dimensionless), $H$ the
  nominal output half range (`output_half_range`) and $U$ the std of the nominal
  $u = F(v)$;
- a clearance (dead band) in the feedback path,
  $\phi = k\,(w - \mathrm{clip}(w, -b, b))$ (`fb_gain` in $u$ per $w$, `fb_band`
  $= b \ge 0$).

Neutral: $k_3 = k = b = 0$ ($\phi \equiv 0$).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext, output_half_range


def feedback_force(
    w: Float[Array, ""],
    half: Float[Array, ""],
    u_scale: Float[Array, ""],
    k3: Float[Array, ""],
    gain: Float[Array, ""],
    band: Float[Array, ""],
) -> Float[Array, ""]:
    r"""$\phi(w) = k_3 (w/H)^3 U + k\,(w - \mathrm{clip}(w, -b, b))$; exactly 0 at the
    neutral values."""
    return k3 * (w / half) ** 3 * u_scale + gain * (w - jnp.clip(w, -band, band))


class FeedbackNonlinearityEffect(AbstractEffect):
    """Cubic stiffness or a clearance in a feedback path from $w$ to $u$."""

    name = "feedback_nonlinearity"
    slots = ("fb_cubic", "fb_gain", "fb_band")
    neutral = {"fb_cubic": 0.0, "fb_gain": 0.0, "fb_band": 0.0}
    positive = ("fb_band",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        half = output_half_range(ctx)
        return {
            "fb_cubic": 0.05,
            "fb_gain": 0.1 * ctx.u_std / half,
            "fb_band": 0.05 * half,
        }

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        half = output_half_range(ctx)
        return [
            {"fb_cubic": 0.05},
            {"fb_gain": 0.2 * ctx.u_std / half, "fb_band": 0.3 * half},
        ]
