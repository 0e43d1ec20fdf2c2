"""`backlash`: a play operator of total width $c$ on $v$ before $F$, with an
optional stick-slip jump $J$ (a sticky control valve), or a play of width $c_o$ on
the output $w$ of $G$ (slot `out_backlash`: a gear between a drive and the load
whose position is measured).

**Where the play sits.** A play on $v$ is the backlash of a valve or of a
linkage in front of the drive: the load follows a play operator of the command.
In a servo whose gear lies between the motor (the drive's own lag, part of $G$)
and a stiff load, the play acts on the motor's position, after the drive's
dynamics: the hysteresis model of gear backlash for a stiff transmission
(Nordin & Gutman 2002; the dead-zone model is the compliant one) at the output
of $G$, as in Tao & Kokotovic (1995, output backlash):
$y = h(\\mathrm{play}_{c_o}(w))$. The two are not
interchangeable: after a reversal a play on $v$ holds the input of $G$, so the
whole response waits until $v$ has crossed the band, while a play on $w$ lets
$G$'s own lag run on and holds only the load. A row frees one placement, and the
report says which (`placement`). The output play stands for the class only where
it beats the play on $v$ on both records (`AbstractEffect.alternative`): in a
closed loop a wide play on the measured output can follow the estimation record
and not the validation one. It starts at rest at 0, the output of $G$ at rest.

With $J > 0$ this is the two-parameter stiction model in the form of He, Wang,
Pottmann & Qin (2007, Fig. 3), in the parameters of Choudhury, Thornhill & Shah
(2005): $S = c$ (dead band plus stick band) and the slip jump $J$, i.e. a static
band $f_s = (S + J)/2$ and a kinetic band $f_d = (S - J)/2$. The valve stays
where it is until the input has moved more than $f_s$ away from it, then jumps to
within $f_d$ of the input (a jump of $J$ past the plain play operator).

With a slide jump $J_c > 0$ instead (slot `slide_jump`) it is the data-driven
model of Choudhury, Thornhill & Shah (2005, Sec. 4, Fig. 7), same $S$: after a
slip the valve keeps sliding at $x - \\mathrm{sign}(\\dot x)(S - J_c)/2$ while its
input keeps its direction, sticks when the input stops or reverses, and slips
again once the input has moved from there by more than $S$ against, or $J_c$
along, its last direction (`slide_step`).

**Where the valve starts.** The contract starts the play at rest at $v_0$
(centred). A record cut from a loop's operation starts wherever the valve was
stuck: anywhere within its band of the command, a level that an integrating
process turns into a ramp until the first slip. Slot `valve_start` ($\\delta$,
neutral 0) starts the play, the slip and the slide stuck at $v_0 + \\delta$; the
stick-slip profile's starts free it (`layout.stick_slip_profile`, closed-loop
records only), and the validation record's own start is found by
`fit.validation_start` (an initial state estimated on each record, as
prediction-error validation does: Ljung 1999, §14.3 and §16.6).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, StartContext, scale_span, span


def output_span(ctx: StartContext) -> float:
    """The 2 %-98 % range of the nominal output (never 0): the unit of the output
    play."""
    wq = ctx.w_quantiles
    return max(wq[0.98] - wq[0.02], 1e-12)


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


SlideState = tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]


def slide_init(x0: Float[Array, ""]) -> SlideState:
    """The state `(x_ss, direction, stuck)` of `slide_step` at rest at `x0`: stuck
    there, no direction yet (the first motion must cross $S$)."""
    x0 = jnp.asarray(x0)
    return x0, jnp.zeros_like(x0), jnp.ones_like(x0)


def slide_step(
    y_prev: Float[Array, ""],
    state: SlideState,
    x_prev: Float[Array, ""],
    x: Float[Array, ""],
    width: Float[Array, ""],
    jump: Float[Array, ""],
) -> tuple[Float[Array, ""], SlideState]:
    """One step of Choudhury et al.'s (2005, Fig. 7) valve, $S$ = `width`, $J$ =
    `jump`: `(y, state)` from the position `y_prev`, the state `(x_ss, direction,
    stuck)` (`slide_init`; floats, a scan carry with tangents) and the inputs
    `x_prev`, `x`.

    Sliding, it goes on at $y = x - d\\,(S - J)/2$ while $\\mathrm{sign}(x -
    x_{prev}) = d$, else sticks with $x_{ss} = x_{prev}$; stuck, it slips to $y =
    x - s\\,(S - J)/2$, $s = \\mathrm{sign}(x - x_{ss})$, once $|x - x_{ss}| > J$
    ($s = d$) or $> S$ (else). Exact: $y$ moves with $S$, $J$ through $(S - J)/2$
    only (tangents $\\mp d/2$), the instants of sticking and slipping not at all.
    """
    x_ss, direction, stuck = state
    # sliding, the direction is +-1, so a still input (sign 0) does not go on;
    # the bands are >= 0, so a slip has x != x_ss: few operations (this runs in
    # every memory row's scan, tangents and all)
    goes_on = (stuck < 0.5) & (jnp.sign(x - x_prev) == direction)
    x_ss = jnp.where((stuck < 0.5) & ~goes_on, x_prev, x_ss)
    d = jnp.sign(x - x_ss)
    slips = ~goes_on & (jnp.abs(x - x_ss) > jnp.where(d == direction, jump, width))
    direction = jnp.where(slips, d, direction)
    moves = goes_on | slips
    y = jnp.where(moves, x - direction * (width - jump) / 2, y_prev)
    return y, (x_ss, direction, (~moves).astype(stuck.dtype))


class BacklashEffect(AbstractEffect):
    """Play of width $c \\ge 0$ (neutral $c = 0$) with a slip jump $J \\ge 0$ (He
    et al.) or a slide jump $J_c \\ge 0$ (Choudhury et al.), neutral $0$ each: the
    plain play operator; or a play of width $c_o \\ge 0$ on the output of $G$
    (`out_backlash`, neutral 0); the play starts stuck at $v_0 + \\delta$
    (`valve_start`, neutral 0)."""

    name = "backlash"
    slots = ("backlash", "slip_jump", "slide_jump", "out_backlash", "valve_start")
    neutral = {
        "backlash": 0.0,
        "slip_jump": 0.0,
        "slide_jump": 0.0,
        "out_backlash": 0.0,
        "valve_start": 0.0,
    }
    positive = ("backlash", "slip_jump", "slide_jump", "out_backlash")
    extension = ("slip_jump", "slide_jump")
    alternative = ("out_backlash",)
    # the profile's starts beside a fitted nominal free an output level
    # (`layout.stick_slip_profile`), which their linear twin frees too
    level = ("out_off",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        unit = 0.05 * scale_span(ctx)
        return {
            "backlash": unit,
            "slip_jump": unit,
            "slide_jump": unit,
            "out_backlash": 0.05 * output_span(ctx),
            "valve_start": unit,
        }

    def placement(self, free: set[str]) -> str:
        """Where a row freeing `free` put the play: "output" (`out_backlash`, after
        $G$) or "input" (on $v$, before $F$)."""
        return "output" if "out_backlash" in free else "input"

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        # the plain play at two widths, each with a slip jump of half of it, and
        # the best points of the profile in (f_s, f_d) of each variant
        # (`ctx.stick_slip`, its jump's slot named; the slide only there): the
        # exact step gives f_s no derivative, and the tangents of S and J are
        # opposite (both reach x only through f_d), so a fit moves f_d at about
        # the f_s it starts from; the profile's gain (or identity map) starts the
        # re-fit's
        plain = [{"backlash": 0.04 * span(ctx)}, {"backlash": 0.2 * span(ctx)}]
        sticky = [{**s, "slip_jump": 0.5 * s["backlash"]} for s in plain]
        profile = [
            {"backlash": S, slot: J, **refit} for S, J, refit, slot in ctx.stick_slip
        ]
        # the play on the output at the same two fractions of the output's range
        output = [{"out_backlash": f * output_span(ctx)} for f in (0.04, 0.2)]
        return plain + sticky + profile + output
