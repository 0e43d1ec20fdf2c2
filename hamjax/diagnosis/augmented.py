"""The universal augmented model: the nominal Hammerstein plant with every catalogue
effect in place, each at a parameter slot whose neutral value removes it.

$v \\to$ delay $\\to$ rate limit $\\to$ backlash $\\to$ dead zone $\\to F \\to$ preload
$\\to$ saturation $\\to$ extra pole $\\to G \\to$ output play $\\to h$ (output map), and a feedback
path from the output of $G$ to its input: $u' = u - f(\\text{velocity}) - \\phi(w)$
(`friction`, `feedback_nonlinearity`).

**The feedback loop** runs the filter and the fed-back forces in one scan
(`feedback_scan`): at step $k$ the filter's output before consuming $u_k$ is
$\\hat w_k = z_0 + b_0 s_k$ ($s_k$ the input side's output), at which the feedback
nonlinearity $\\phi$ is evaluated; the friction acts on the velocity over the
step, solved implicitly for $u_k$ (it sticks rather than chatters); then the
filter consumes $u_k$. For $b_0 = 0$ (every zero-order-hold discretised strictly
proper block) $\\hat w_k = w_k$ and the loop is exact; for $b_0 \\ne 0$ (an
algebraic loop) this is the one-step convention that the forces see the output
without its own feedthrough. Without a freed feedback slot the plain filter scan
(`filter_scan`) runs instead; with every feedback slot neutral the loop gives the same numbers.

One shape of model for every case and every candidate means one compilation: a
candidate is a *row* (which slots it frees, where it starts, its delay), a case is
a `CaseArrays` (padded records and the nominal model in a fixed-size form), and
`jax.vmap` runs all rows of all cases together.

The linear block is held in a fixed-size state space of order `n_max`:
a discrete $B/A$ is zero-padded (the response is unchanged); a continuous
$\\text{num}/\\text{den}$ of order $n$ is multiplied above and below by
$(s + \\lambda)^{n_{max} - n}$ (an exactly cancelling factor) and discretised by
the zero-order hold, so its denominator coefficients stay the free parameters.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._filters import df2t_step, expm_taylor, filter_scan, zoh_tf
from .._linalg import charpoly_adjugate, polymul
from ..models.nonlinearities.backlash import Backlash, BacklashState
from ..models.nonlinearities.piecewise_linear import (
    PARAMETERS as PL_PARAMETERS,
    piecewise_linear_map,
)
from .effects._base import UNIT_MAX, StartContext, unit_raw
from .effects.backlash import (
    BacklashEffect,
    play_step,
    slide_init,
    slide_step,
    stick_slip_step,
)
from .effects.dead_zone import DeadZoneEffect, dead_zone
from .effects.extra_pole import ExtraPoleEffect, lag_factor
from .effects.feedback_nonlinearity import (
    FeedbackNonlinearityEffect,
    feedback_force,
)
from .effects.friction import EPS_FRACTION, FrictionEffect, friction_force
from .effects.output_nonlinearity import OutputNonlinearityEffect, output_map
from .effects.preload import PreloadEffect, add_preload
from .effects.rate_limit import RateLimitEffect, rate_limit_step
from .effects.saturation import SaturationEffect, saturate
from .effects.time_delay import TimeDelayEffect, delay, fractional_split


NOMINAL_SLOTS = (*PL_PARAMETERS, "in_scale", "out_scale", "gain")
# The deterministic effects in the order of the signal chain above; each owns its
# slots (neutral value, transform, scale) in its own file under `effects/`.
CHAIN = (
    TimeDelayEffect(),  # its whole part is the row's `tau`
    RateLimitEffect(),
    BacklashEffect(),
    DeadZoneEffect(),
    PreloadEffect(),
    SaturationEffect(),
    ExtraPoleEffect(),
    FrictionEffect(),
    FeedbackNonlinearityEffect(),
    OutputNonlinearityEffect(),
)
EFFECT_SLOTS = tuple(slot for effect in CHAIN for slot in effect.slots)
EFFECT_NEUTRAL = {
    slot: effect.neutral[slot] for effect in CHAIN for slot in effect.slots
}
# Slots whose physical value is |raw| (widths and rates are non-negative), and those
# mapped smoothly into [0, 1) (the extra pole).
_ABS_SLOTS = tuple(slot for effect in CHAIN for slot in effect.positive)
_UNIT_SLOTS = tuple(slot for effect in CHAIN for slot in effect.unit_interval)
NL_IDENTITY, NL_PIECEWISE, NL_TABULATED, NL_BACKLASH = 0, 1, 2, 3
# the kinds whose map reads the tables (`tab_v`, `tab_u`, `tab_d`)
TABLE_KINDS = (NL_TABULATED, NL_BACKLASH)


def raw_from_physical(name: str, value: float) -> float:
    """Inverse of the slot transform (used to place starting values)."""
    return unit_raw(value) if name in _UNIT_SLOTS else float(value)


def effect_scales(ctx: StartContext) -> dict[str, float]:
    """The scale of every effect slot, from the effects that own them."""
    return {k: v for effect in CHAIN for k, v in effect.scales(ctx).items()}


def slot_names(n_max: int) -> tuple[str, ...]:
    """Names of the full parameter vector: nominal, effects, `den1..den{n_max}`,
    then `db0..db{n_max}` (changes of a discrete numerator, `REFIT_LINEAR`)."""
    return (
        NOMINAL_SLOTS
        + EFFECT_SLOTS
        + tuple(f"den{i}" for i in range(1, n_max + 1))
        + numerator_slots(n_max)
    )


def numerator_slots(n_max: int) -> tuple[str, ...]:
    """`db0..db{n_max}`: added to the nominal's discrete numerator (neutral 0)."""
    return tuple(f"db{i}" for i in range(n_max + 1))


def n_max_of(n_slots: int) -> int:
    """The linear block's padded order from the length of the parameter vector."""
    return (n_slots - len(NOMINAL_SLOTS) - len(EFFECT_SLOTS) - 1) // 2


def slot_index(name: str, n_max: int) -> int:
    return slot_names(n_max).index(name)


class CaseArrays(eqx.Module):
    """One case in fixed-size form (records padded to a common length `L`)."""

    v_est: Float[Array, " L"]
    y_est: Float[Array, " L"]
    m_est: Float[Array, " L"]  # 1 on real samples, 0 on padding
    v_val: Float[Array, " L"]
    y_val: Float[Array, " L"]
    m_val: Float[Array, " L"]
    dt: Float[Array, ""]
    is_ct: Float[Array, ""]  # 1.0 for a continuous linear block
    nl_kind: Int[Array, ""]
    tab_v: Float[Array, " T"]
    tab_u: Float[Array, " T"]  # the map, or a backlash's ascending border
    tab_d: Float[Array, " T"]  # a backlash's descending border (else `tab_u`)
    b_disc: Float[Array, " n1"]  # discrete numerator, padded to n_max + 1
    ct_num: Float[Array, " n1"]  # continuous numerator x pad factor, monic den
    ct_pad: Float[Array, " n1"]  # the cancelling factor (s + lambda)^(n_max - n)
    den_lead: Float[Array, ""]  # leading coefficient of the padded continuous den
    anchor: Float[Array, " S"]  # raw value of each slot at theta = 0
    scale: Float[Array, " S"]  # raw = anchor + scale * theta
    neutral: Float[Array, " S"]  # physical value when the slot is not free
    out_centre: Float[Array, ""]
    out_half: Float[Array, ""]
    y_scale: Float[Array, ""]
    u_scale: Float[Array, ""]  # std of the nominal u = F(v) (estimation)
    dw_half: Float[Array, ""]  # velocity scale of dw/dt (`StartContext.dw_half`)
    # weight of the Gaussian prior at nominal on the scaled re-fit parameters
    # (`layout.prior_weight`, the user's stated nominal uncertainty)
    prior_weight: Float[Array, ""]
    # the fixed noise filter of a prediction-error fit, e = (f0 + f1 q^-1 + f2 q^-2)
    # / (1 + g q^-1) r (`schedule.whitening_items`); the identity (1, 0, 0), 0:
    # output error
    noise_fir: Float[Array, " 3"]
    noise_ar: Float[Array, ""]
    # the filter's direction in its one free parameter (the predictor's pole or
    # gain, fitted jointly with the row: `fit.normal_equations`); zero: fixed
    noise_dfir: Float[Array, " 3"]
    noise_dar: Float[Array, ""]


class Row(eqx.Module):
    """One candidate start: `idx[j]` is the slot moved by `theta[j]` (`S` = unused);
    a slot not `free` is held at `held` (physical: the case's `neutral`, except
    where a start holds the nominal's map at the identity, `layout.prepare`)."""

    idx: Int[Array, " P"]
    theta0: Float[Array, " P"]
    tau: Int[Array, ""]
    free: Bool[Array, " S"]
    held: Float[Array, " S"]


def full_parameters(
    theta: Float[Array, " P"], row: Row, case: CaseArrays
) -> Float[Array, " S"]:
    """Physical full parameter vector of a row at compact parameters `theta`."""
    n_slots = case.anchor.shape[0]
    moved = jnp.zeros(n_slots, theta.dtype).at[row.idx].add(theta, mode="drop")
    raw = case.anchor + case.scale * moved
    n_max = n_max_of(n_slots)
    is_abs = np.isin(np.array(slot_names(n_max)), _ABS_SLOTS)
    is_unit = np.isin(np.array(slot_names(n_max)), _UNIT_SLOTS)
    phys = jnp.where(is_abs, jnp.abs(raw), raw)
    phys = jnp.where(is_unit, UNIT_MAX * jax.nn.sigmoid(raw), phys)
    # `where`, not arithmetic, so the infinite neutral values never meet a tangent.
    return jnp.where(row.free, phys, row.held)


def linear_polynomials(p: Float[Array, " S"], case: CaseArrays) -> tuple[Array, Array]:
    """Discrete `(b, a)` in $q^{-1}$ of the re-fitted linear block, length `n_max + 1`
    (a discrete numerator is $g\\,(b_{nominal} + \\delta b)$, `db0..`).

    A continuous block is discretised exactly (zero-order hold, matrix exponential)
    and converted to its transfer function by Faddeev-LeVerrier.
    """
    n_max = case.b_disc.shape[0] - 1
    g = p[NOMINAL_SLOTS.index("gain")]
    first_den = len(NOMINAL_SLOTS) + len(EFFECT_SLOTS)
    den = p[first_den : first_den + n_max]
    db = p[first_den + n_max :]
    a_disc = jnp.concatenate([jnp.ones(1), den])
    den_ct = polymul(jnp.concatenate([case.den_lead[None], den]), case.ct_pad)
    den_ct = den_ct[-(n_max + 1) :]
    Ad, Bd, Cc, Dc = zoh_tf(g * case.ct_num, den_ct, case.dt, expm=expm_taylor)
    c, Ms = charpoly_adjugate(Ad)
    # b_j = C M_j B + D c_j (coefficient of z^{n-j}), j = 1..n
    cmb = jnp.einsum("i,kij,j->k", Cc[0], Ms, Bd[:, 0])
    b_ct = jnp.concatenate([Dc[0], cmb + Dc[0, 0] * c[1:]])
    ct = case.is_ct > 0.5
    # `db` moves a discrete numerator only (a continuous block never frees it)
    return jnp.where(ct, b_ct, g * (case.b_disc + db)), jnp.where(ct, c, a_disc)


def switch(flag: bool | Bool[Array, ""], on: Callable, off: Callable, *args):
    """`on(*args)` if `flag` else `off(*args)`: chosen when tracing for a Python
    bool (the other branch is not compiled), at run time (`lax.cond`) for a traced
    flag, which must be the same for a whole batch (not mapped over)."""
    if flag is True:
        return on(*args)
    if flag is False:
        return off(*args)
    return lax.cond(flag, on, off, *args)


def _table(v: Array, p: Float[Array, " S"], case: CaseArrays) -> Array:
    si, so = p[NOMINAL_SLOTS.index("in_scale")], p[NOMINAL_SLOTS.index("out_scale")]
    return so * jnp.interp(si * v, case.tab_v, case.tab_u)


BISECTIONS = 20  # halvings of the friction step's bracket (`feedback_scan`)


def feedback_scan(
    b: Array,
    a: Array,
    s: Float[Array, " B"],
    z: Float[Array, " n"],
    phi: Callable[[Array], Array],
    friction: Callable[[Array, Array], Array],
    bound: Float[Array, ""],
    dt: Float[Array, ""],
) -> tuple[Float[Array, " n"], Float[Array, " B"]]:
    """The filter with the fed-back forces subtracted from its input, from the
    filter state `z`: `(z_end, w)` (chains over blocks like `filter_scan`).

    At step $k$: $\\hat w_k = z_0 + b_0 s_k$ and $s'_k = s_k - \\phi(\\hat w_k)$
    (explicit); the friction acts on the velocity over the step, $w_{k+1}$ and
    $(w_{k+1} - w_k)/dt$, both affine in $u_k$ (direct form II transposed:
    $w_{k+1} = z_1 - a_1 z_0 + (b_1 - a_1 b_0) u_k$ up to $b_0 u_{k+1}$), so $u_k$
    solves $u = s'_k - $ `friction(v_w(u), v_dw(u))` (implicit, the discrete
    form of Coulomb friction that sticks instead of chattering). The root lies in
    $s'_k \\pm$ `bound` ($|f| \\le c_w + c_{dw}$): `BISECTIONS` halvings and a
    Newton step (no tangents), then a Newton step that carries the tangents of
    the implicit function. After 20 halvings the velocity is within
    $2 \\cdot 10^{-6}$ of the bracket's velocity span, far inside the smoothing
    width ($10^{-3}$ of the velocity scale), where Newton converges
    quadratically: two steps reach rounding.
    """

    def step(z, sk):
        w_hat = b[0] * sk + z[0]
        s2 = sk - phi(w_hat)
        a_w, b_w = z[1] - a[1] * z[0], b[1] - a[1] * b[0]
        a_d, b_d = (a_w - z[0]) / dt, (b_w - b[0]) / dt

        def g(u):
            return u - s2 + friction(a_w + b_w * u, a_d + b_d * u)

        def bisect(_, lohi):
            lo, hi = lohi
            mid = 0.5 * (lo + hi)
            up = lax.stop_gradient(g(mid)) > 0
            return jnp.where(up, lo, mid), jnp.where(up, mid, hi)

        c = lax.stop_gradient(bound)
        lo, hi = lax.stop_gradient(s2) - c, lax.stop_gradient(s2) + c
        lo, hi = lax.fori_loop(0, BISECTIONS, bisect, (lo, hi))

        def newton(u):
            g0, slope = jax.jvp(g, (u,), (jnp.ones_like(u),))
            return u - g0 / slope

        uk = newton(lax.stop_gradient(newton(0.5 * (lo + hi))))
        return df2t_step(b, a, z, uk)

    return lax.scan(step, z, s, unroll=1)


def feedback_arguments(p: Float[Array, " S"], case: CaseArrays) -> tuple:
    """`(phi, friction, bound)` of `feedback_scan` at parameters `p`: the
    feedback nonlinearity $w \\mapsto \\phi(w)$, the friction
    $(v_w, v_{dw}) \\mapsto f$ and $c_w + c_{dw}$; all 0 at the neutral values."""
    at = named(p, case)
    eps_w, eps_dw = EPS_FRACTION * case.out_half, EPS_FRACTION * case.dw_half

    def phi(w):
        return feedback_force(w, at, case.out_half, case.u_scale)

    def friction(v_w, v_dw):
        return friction_force(v_w, v_dw, at, eps_w, eps_dw)

    return phi, friction, at("fric_w") + at("fric_dw")


def linear_part(
    b: Array,
    a: Array,
    u: Float[Array, " B"],
    z: Float[Array, " n"],
    p: Float[Array, " S"],
    case: CaseArrays,
    feedback: bool | Bool[Array, ""] = True,
) -> tuple[Float[Array, " n"], Float[Array, " B"]]:
    """The linear block from the filter state `z`: `(z_end, w)`, with the
    feedback loop (`feedback_scan`) or, for `feedback=False`, without it
    (`filter_scan`, exact when every feedback slot is neutral)."""

    def loop(u, z):
        return feedback_scan(b, a, u, z, *feedback_arguments(p, case), case.dt)

    def plain(u, z):
        return filter_scan(b, a, u, z)

    return switch(feedback, loop, plain, u, z)


class NominalBacklash(eqx.Module):
    """A backlash nominal in the memory scan: borders tabulated on `case.tab_v`
    (`tab_u` ascending, `tab_d` descending), read at `in_scale` times its input,
    output times `out_scale`; `on` is False for every other kind (then ignored)."""

    in_scale: Float[Array, ""]
    out_scale: Float[Array, ""]
    tab_v: Float[Array, " T"]
    tab_u: Float[Array, " T"]
    tab_d: Float[Array, " T"]
    on: Bool[Array, ""]

    def operator(self) -> Backlash:
        return Backlash.from_table(self.tab_v, self.tab_u, self.tab_d)

    def init(self, x0: Float[Array, ""]) -> tuple[Array, ...]:
        """The operator's state at its first input (centred in the play), with
        the border flags as floats (a scan carry with tangents)."""
        return _float_state(self.operator().init(self.in_scale * x0))

    def step(self, state: tuple[Array, ...], x: Float[Array, ""]):
        """`Backlash.step` (seed 000's semantics) on `in_scale * x`."""
        v_prev, u, on_a, on_d = state
        bools = BacklashState(v_prev, u, on_a > 0.5, on_d > 0.5)
        new, u = self.operator().step(bools, self.in_scale * x)
        return _float_state(new), jnp.where(self.on, self.out_scale * u, x)


def _float_state(state: BacklashState) -> tuple[Array, ...]:
    v_prev, u, on_a, on_d = state
    return v_prev, u, on_a.astype(u.dtype), on_d.astype(u.dtype)


def memory_scan(
    v: Float[Array, " B"],
    state: tuple,
    p: Float[Array, " S"],
    case: CaseArrays,
    table: bool | Bool[Array, ""] = True,
) -> tuple[tuple, Float[Array, " B"]]:
    """Rate limit, play operator with slip jump (`stick_slip_step`) or slide jump
    (`slide_step`), then a backlash nominal, at parameters `p`
    (`memory_arguments`), from `state` (`memory_init`: rate-limited input, play
    output, the slide's state, nominal backlash state): `(state_end, x)` (one
    scan; chains over blocks like `filter_scan`). A zero slide jump leaves the
    play's arithmetic as it is. `table=False` skips the nominal backlash (exact
    unless the case has one)."""
    max_step, width, jump, slide, _, nominal = memory_arguments(p, case)

    def step(carry, vk, with_nominal):
        x_prev, xb, ss, bl = carry
        xr = rate_limit_step(x_prev, vk, max_step)
        xs, ss = slide_step(xb, ss, x_prev, xr, width, slide)
        xb = jnp.where(slide > 0, xs, stick_slip_step(xb, xr, width, jump))
        if not with_nominal:
            return (xr, xb, ss, bl), xb
        bl, x = nominal.step(bl, xb)
        return (xr, xb, ss, bl), x

    def run(with_nominal):
        return lambda v, state: lax.scan(
            lambda c, vk: step(c, vk, with_nominal), state, v, unroll=1
        )

    return switch(table, run(True), run(False), v, state)


def memory_init(v0: Float[Array, ""], p: Float[Array, " S"], case: CaseArrays):
    """The state of `memory_scan` at rest at its first input $v_0$: the rate
    limit at $v_0$, the play at $v_0 + \\delta$ (`valve_start`; centred at
    $\\delta = 0$), the slide stuck there (`slide_init`), the nominal backlash
    centred in its play."""
    *_, start, nominal = memory_arguments(p, case)
    return (v0, v0 + start, slide_init(v0 + start), nominal.init(v0))


def input_memory(
    v: Float[Array, " L"],
    p: Float[Array, " S"],
    case: CaseArrays,
    table: bool | Bool[Array, ""] = True,
) -> Float[Array, " L"]:
    """Rate limit, play (with slip or slide jump) and a backlash nominal, all
    started at $v_0$."""
    return memory_scan(v, memory_init(v[0], p, case), p, case, table)[1]


def output_play_scan(
    w: Float[Array, " B"],
    prev: Float[Array, ""],
    p: Float[Array, " S"],
    case: CaseArrays,
) -> tuple[Float[Array, ""], Float[Array, " B"]]:
    """The play of width `out_backlash` on the output of $G$ from its previous
    output `prev`: `(last, played)` (chains over blocks like `filter_scan`).

    Where the width is 0 (every row that does not free it) `w` is returned as it
    is, tangents included: a clamp to $[w_k, w_k]$ has the value $w_k$ but,
    where $w$ holds still, a tie in its derivative. (An associative scan of the
    clamps, which compose into clamps, gives the same values but took the 80
    loops of seed 1 from 245 s to 340 s: a sequential scan it is.)"""
    width = named(p, case)("out_backlash")

    def step(x_prev, wk):
        x = play_step(x_prev, wk, width)
        return x, x

    last, played = lax.scan(step, prev, w, unroll=1)
    neutral = width == 0
    return jnp.where(neutral, w[-1], last), jnp.where(neutral, w, played)


def output_memory(
    w: Float[Array, " L"], p: Float[Array, " S"], case: CaseArrays
) -> Float[Array, " L"]:
    """`output_play_scan` from rest (the output of $G$ at rest is 0)."""
    return output_play_scan(w, jnp.zeros((), w.dtype), p, case)[1]


def named(p: Float[Array, " S"], case: CaseArrays) -> Callable[[str], Array]:
    """`at(name)`: the physical value of slot `name` (one index, taken on use)."""
    n_max = case.b_disc.shape[0] - 1
    return lambda name: p[slot_index(name, n_max)]


def filter_coefficients(p: Float[Array, " S"], case: CaseArrays) -> tuple[Array, Array]:
    """`(b, a)` of the whole linear part: the re-fitted block times the extra lag
    (`extra_pole.lag_factor`: $(1-p)/(1-p q^{-1})$ or its continuous form, two
    taps either way) and the delay's fraction of a sample
    (`time_delay.fractional_split`; linear, so folded into one filter)."""
    b, a = linear_polynomials(p, case)
    at = named(p, case)
    num, den = lag_factor(*(jnp.clip(at(n), 0.0, 0.995) for n in ("pole", "lag_pole")))
    b, a = polymul(b, num), polymul(a, den)
    return fractional_split(b, a, at("delay_frac"))


def memory_arguments(p: Float[Array, " S"], case: CaseArrays) -> tuple:
    """`(max_step, width, jump, slide, start, nominal)` of the input-memory scan
    (rate limit per sample, play with its slip or slide jump and its start, the
    nominal backlash)."""
    at = named(p, case)
    nominal = NominalBacklash(
        at("in_scale"),
        at("out_scale"),
        case.tab_v,
        case.tab_u,
        case.tab_d,
        case.nl_kind == NL_BACKLASH,
    )
    jumps = at("backlash"), at("slip_jump"), at("slide_jump")
    return at("rate") * case.dt, *jumps, at("valve_start"), nominal


def static_part(
    x: Array,
    p: Float[Array, " S"],
    case: CaseArrays,
    table: bool | Bool[Array, ""] = True,
) -> Array:
    """Dead zone, $F$, preload and saturation: the memoryless input side.

    $F$ is the nominal static map with re-fitted parameters (the identity for a
    backlash nominal, which runs in the input-memory scan: `memory_scan`);
    `table=False` skips the table look-up (exact unless the map is tabulated); a
    traced `table` that is the same for a whole batch skips it at run time.
    """
    at = named(p, case)
    vd = dead_zone(x, at("dz_lo"), at("dz_hi"))
    pl = piecewise_linear_map(vd, *(p[i] for i in range(6)))
    tab = switch(table, _table, lambda v, *_: jnp.zeros_like(v), vd, p, case)
    f = jnp.where(
        case.nl_kind == NL_PIECEWISE,
        pl,
        jnp.where(case.nl_kind == NL_TABULATED, tab, vd),
    )
    u = add_preload(f, vd, at("preload"))
    return saturate(u, at("sat_lo"), at("sat_hi"))


def output_part(w: Array, p: Float[Array, " S"], case: CaseArrays) -> Array:
    """The output map $h$ (`output_nonlinearity`)."""
    return output_map(w, named(p, case), case.out_centre, case.out_half)


def simulate_augmented(
    p: Float[Array, " S"],
    tau: Int[Array, ""],
    v: Float[Array, " L"],
    case: CaseArrays,
    memory: bool | Bool[Array, ""] = True,
    feedback: bool | Bool[Array, ""] = True,
) -> Float[Array, " L"]:
    """Output of the augmented model at physical parameters `p`, from rest.

    `memory=False` skips the input-memory scan (rate limit, backlash and a
    backlash nominal) and the output play, which is exact when the first two
    and the output play are at their neutral values and the map is not a
    backlash; a traced `memory` that is the same
    for a whole batch (not mapped over) skips it at run time for that batch.
    `feedback=False` likewise runs the plain filter instead of the feedback loop
    (exact when `friction` and `feedback_nonlinearity` are neutral).
    """
    b, a = filter_coefficients(p, case)
    return simulate_with_filter(p, b, a, tau, v, case, memory, feedback=feedback)


def simulate_with_filter(
    p: Float[Array, " S"],
    b: Array,
    a: Array,
    tau: Int[Array, ""],
    v: Float[Array, " L"],
    case: CaseArrays,
    memory: bool | Bool[Array, ""] = True,
    table: bool | Bool[Array, ""] = True,
    feedback: bool | Bool[Array, ""] = True,
) -> Float[Array, " L"]:
    """`simulate_augmented` with the filter `(b, a) = filter_coefficients(p, case)`
    already at hand (a fit has it; the matrix exponential is not repeated)."""
    v = delay(v, tau)
    x = switch(memory, input_memory, lambda v, *_: v, v, p, case, table)
    rest = jnp.zeros(a.shape[0] - 1, v.dtype)
    _, w = linear_part(b, a, static_part(x, p, case, table), rest, p, case, feedback)
    w = switch(memory, output_memory, lambda w, *_: w, w, p, case)
    return output_part(w, p, case)


def simulate_row(
    theta: Float[Array, " P"], row: Row, v: Float[Array, " L"], case: CaseArrays
) -> Float[Array, " L"]:
    """`simulate_augmented` at a row's compact parameters (every scan run)."""
    return simulate_augmented(full_parameters(theta, row, case), row.tau, v, case)


# the slots of the scans with memory that `memory=False` skips: the input-memory
# scan and the output play
MEMORY_SLOTS = RateLimitEffect.slots + BacklashEffect.slots


def uses_memory(
    free: Bool[Array, "*batch S"], nl_kind: Int[Array, "*batch"] | int = NL_IDENTITY
) -> Bool[Array, "*batch"]:
    """Whether rows with these free slots, of cases of map kind `nl_kind`, need the
    input-memory scan or the output play (every row of a backlash nominal does)."""
    n_max = n_max_of(free.shape[-1])
    cols = [slot_index(name, n_max) for name in MEMORY_SLOTS]
    return free[..., cols].any(axis=-1) | (nl_kind == NL_BACKLASH)


def uses_table(nl_kind: Int[Array, "*batch"]) -> Bool[Array, "*batch"]:
    """Whether cases of these map kinds read the tables (`TABLE_KINDS`)."""
    return (nl_kind == NL_TABULATED) | (nl_kind == NL_BACKLASH)


FEEDBACK_SLOTS = FrictionEffect.slots + FeedbackNonlinearityEffect.slots


def uses_feedback(free: Bool[Array, "*batch S"]) -> Bool[Array, "*batch"]:
    """Whether rows with these free slots need the feedback loop (`feedback_scan`)."""
    n_max = n_max_of(free.shape[-1])
    cols = [slot_index(name, n_max) for name in FEEDBACK_SLOTS]
    return free[..., cols].any(axis=-1)


simulate_rows = jax.vmap(simulate_row, in_axes=(0, 0, None, None))
