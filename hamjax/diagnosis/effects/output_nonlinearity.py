"""`output_nonlinearity`: $y = h(w) + e$ with $h$ static and not affine."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._base import FLIP_SIGN, AbstractEffect, StartContext, output_half_range


def output_map(
    w: Float[Array, "*shape"],
    centre: Float[Array, ""],
    half: Float[Array, ""],
    q2: Float[Array, ""],
    q3: Float[Array, ""],
    lower: Float[Array, ""],
    upper: Float[Array, ""],
    band: Float[Array, ""],
    sign_blind: Float[Array, ""],
) -> Float[Array, "*shape"]:
    """$h(w)$: a partly sign-blind reading $w + a(|w| - w)$ ($a = 1$: $|w|$), then a
    sensor dead band $b$ around 0, a quadratic/cubic bend
    $w + H(q_2\\tilde w^2 + q_3\\tilde w^3)$ with $\\tilde w = (w - m)/H$, then clipping.

    Neutral at $a = 0$, $b = 0$, $q_2 = q_3 = 0$, $[lower, upper] = [-\\infty, \\infty]$.
    """
    o = w + sign_blind * (jnp.abs(w) - w)
    o = o - jnp.clip(o, -band, band)
    s = (o - centre) / half
    o = o + half * (q2 * s**2 + q3 * s**3)
    return jnp.clip(o, lower, upper)


class OutputNonlinearityEffect(AbstractEffect):
    """Four shapes of one class: polynomial bend, sensor saturation, dead band, and
    a sign-blind sensor (`out_abs` $= a \\in [0, 1)$, a unit-interval slot: the
    nearest it comes to $h = |w|$ is $a = 0.995$, which leaves $0.005\\,(|w| - w)$)."""

    name = "output_nonlinearity"
    slots = ("out_q2", "out_q3", "out_lo", "out_hi", "out_db", "out_abs")
    neutral = {
        "out_q2": 0.0,
        "out_q3": 0.0,
        "out_lo": -np.inf,
        "out_hi": np.inf,
        "out_db": 0.0,
        "out_abs": 0.0,
    }
    positive = ("out_db",)
    unit_interval = ("out_abs",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        half = output_half_range(ctx)
        return {
            "out_q2": 0.05,
            "out_q3": 0.05,
            "out_lo": 0.2 * half,
            "out_hi": 0.2 * half,
            "out_db": 0.05 * half,
            "out_abs": 1.0,
        }

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        wq = ctx.w_quantiles
        half = max((wq[0.98] - wq[0.02]) / 2, 1e-12)
        return [
            {"out_q2": 0.0, "out_q3": 0.0},
            {"out_lo": float(wq[0.1]), "out_hi": float(wq[0.9])},
            {"out_db": 0.1 * half},
            {"out_db": 0.3 * half},
            {"out_abs": 0.95},
            # |w| hides the sign of w: from the nominal's own sign the fit stops
            # at a -> 1 with a shrunken gain when the plant's sign is the other
            {"out_abs": 0.95, FLIP_SIGN: 1.0},
        ]
