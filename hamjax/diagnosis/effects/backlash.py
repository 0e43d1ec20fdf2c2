"""`backlash`: a play operator of total width $c$ on $v$ before $F$, with an
optional stick-slip jump $J$ (a sticky control valve).

With $J > 0$ this is the two-parameter stiction model in the form of He, Wang,
Pottmann & Qin (2007, Fig. 3), in the parameters of Choudhury, Thornhill & Shah
(2005): $S = c$ (dead band plus stick band) and the slip jump $J$, i.e. a static
band $f_s = (S + J)/2$ and a kinetic band $f_d = (S - J)/2$. The valve stays
where it is until the input has moved more than $f_s$ away from it, then jumps to
within $f_d$ of the input (a jump of $J$ past the plain play operator).
"""

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


def stick_slip_step(
    x_prev: Float[Array, ""],
    v: Float[Array, ""],
    width: Float[Array, ""],
    jump: Float[Array, ""],
) -> Float[Array, ""]:
    """One step of the play operator of width $S$ with a slip jump $J$:
    $x_k = v_k - f_d$ if $x_{k-1} < v_k - f_s$, $v_k + f_d$ if
    $x_{k-1} > v_k + f_s$, else $x_{k-1}$ (stuck), with $f_s = (S + J)/2$,
    $f_d = (S - J)/2$ (He et al. 2007, Fig. 3: $u_r = v - x$ slips when
    $|u_r| > f_s$ and is then $\\pm f_d$).

    Exact (no smoothing): the position after a slip depends on $J$ through $f_d$
    (derivative $\\mp 1/2$), the instants of the slips only through $f_s$ (no
    derivative: a fit moves $f_d$ at fixed $f_s$, which the starts place). With
    $J = 0$ it is `play_step` exactly, values and tangents.
    """
    kinetic, static = (width - jump) / 2, (width + jump) / 2
    slip = jnp.where(
        x_prev < v - static,
        v - kinetic,
        jnp.where(x_prev > v + static, v + kinetic, x_prev),
    )
    return jnp.where(jump > 0, slip, play_step(x_prev, v, width))


class BacklashEffect(AbstractEffect):
    """Play of width $c \\ge 0$ (neutral $c = 0$) with a slip jump $J \\ge 0$
    (neutral $J = 0$: the plain play operator)."""

    name = "backlash"
    slots = ("backlash", "slip_jump")
    neutral = {"backlash": 0.0, "slip_jump": 0.0}
    positive = ("backlash", "slip_jump")
    extension = ("slip_jump",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        unit = 0.05 * scale_span(ctx)
        return {"backlash": unit, "slip_jump": unit}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        # the plain play at two widths, each with a slip jump of half of it, and
        # the best points of the profile in (f_s, f_d) (`ctx.stick_slip`): the
        # exact step gives f_s no derivative, and the tangents of S and J are
        # opposite (both reach x only through f_d), so a fit moves f_d at about
        # the f_s it starts from; the profile's gain starts the re-fit's gain
        plain = [{"backlash": 0.04 * span(ctx)}, {"backlash": 0.2 * span(ctx)}]
        sticky = [{**s, "slip_jump": 0.5 * s["backlash"]} for s in plain]
        profile = [
            {"backlash": S, "slip_jump": J, "gain": g} for S, J, g in ctx.stick_slip
        ]
        return plain + sticky + profile
