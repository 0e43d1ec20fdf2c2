"""`output_nonlinearity`: $y = h(w) + e$ with $h$ static and not affine."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._base import (
    FLIP_SIGN,
    REFIT_LINEAR,
    AbstractEffect,
    SlotValues,
    StartContext,
    output_half_range,
)


def output_map(
    w: Float[Array, "*shape"],
    at: SlotValues,
    centre: Float[Array, ""],
    half: Float[Array, ""],
) -> Float[Array, "*shape"]:
    """$h(w)$: a partly sign-blind reading $w + a(|w| - w)$ ($a = 1$: $|w|$), then a
    sensor dead band $b$ around 0, a quadratic/cubic bend
    $w + H(q_2\\tilde w^2 + q_3\\tilde w^3)$ with $\\tilde w = (w - m)/H$, then clipping
    to $[lo, hi]$, plus an output level $c$; slots `out_abs` ($a$), `out_db` ($b$),
    `out_q2`, `out_q3`, `out_lo`, `out_hi`, `out_off` ($c$).

    Neutral at $a = 0$, $b = 0$, $q_2 = q_3 = 0$, $[lo, hi] = [-\\infty, \\infty]$,
    $c = 0$.
    """
    o = w + at("out_abs") * (jnp.abs(w) - w)
    o = o - jnp.clip(o, -at("out_db"), at("out_db"))
    s = (o - centre) / half
    o = o + half * (at("out_q2") * s**2 + at("out_q3") * s**3)
    return jnp.clip(o, at("out_lo"), at("out_hi")) + at("out_off")


class OutputNonlinearityEffect(AbstractEffect):
    """Four shapes of one class: polynomial bend, sensor saturation, dead band, and
    a sign-blind sensor (`out_abs` $= a \\in [0, 1)$, a unit-interval slot: the
    nearest it comes to $h = |w|$ is $a = 0.995$, which leaves $0.005\\,(|w| - w)$).

    **Against hamjax's own nominal** (`ctx.refit_linear`: no model.json, the
    nominal is `nominal_fit`'s linear fit) a sign-blind start also re-fits the
    whole linear block and an output level `out_off`. That nominal is the best
    *linear* predictor of y, and an even map voids it: for a symmetric input
    $E[|w_k|\\,v_{k-j}] = 0$, so the fit keeps a numerator of about zero static
    gain (a differentiator) that no pole or gain re-fit turns back into $G$; and
    a record centred on its means leaves $|w|$ a level to fit."""

    name = "output_nonlinearity"
    slots = ("out_q2", "out_q3", "out_lo", "out_hi", "out_db", "out_abs", "out_off")
    neutral = {
        "out_q2": 0.0,
        "out_q3": 0.0,
        "out_lo": -np.inf,
        "out_hi": np.inf,
        "out_db": 0.0,
        "out_abs": 0.0,
        "out_off": 0.0,
    }
    positive = ("out_db",)
    unit_interval = ("out_abs",)
    level = ("out_off",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        half = output_half_range(ctx)
        return {
            "out_q2": 0.05,
            "out_q3": 0.05,
            "out_lo": 0.2 * half,
            "out_hi": 0.2 * half,
            "out_db": 0.05 * half,
            "out_abs": 1.0,
            "out_off": 0.2 * half,
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
        ] + (
            [{"out_abs": 0.95, "out_off": 0.0, REFIT_LINEAR: 1.0}]
            if ctx.refit_linear
            else []
        )
