"""Turn a nominal plant and two records into the fixed-size arrays of the augmented
model, and the candidate catalogue into rows (NumPy; runs once per case)."""

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Float

from .._filters import lfilter_numpy, state_space_numpy, zoh_tf
from ..io.model_json import integrators
from ..models import (
    Backlash,
    ContinuousTransferFunction,
    DiscreteTransferFunction,
    Hammerstein,
    Identity,
    PiecewiseLinear,
    Tabulated,
)
from ..models.hammerstein import fold_output_scale
from ..models.nonlinearities.piecewise_linear import (
    PARAMETERS as PL_PARAMETERS,
    piecewise_linear_map,
)
from .augmented import (
    EFFECT_NEUTRAL,
    EFFECT_SLOTS,
    NL_BACKLASH,
    NL_IDENTITY,
    NL_PIECEWISE,
    NL_TABULATED,
    NOMINAL_SLOTS,
    CaseArrays,
    Row,
    effect_scales,
    numerator_slots,
    raw_from_physical,
    slot_index,
    slot_names,
)
from .effects import (
    BacklashEffect,
    DeadZoneEffect,
    ExtraPoleEffect,
    FeedbackNonlinearityEffect,
    FrictionEffect,
    OutputNonlinearityEffect,
    ParameterMismatch,
    PreloadEffect,
    RateLimitEffect,
    SaturationEffect,
    StartContext,
    TimeDelayEffect,
)
from .effects._base import (
    FLIP_SIGN,
    IDENTITY_MAP,
    REFIT_LINEAR,
    output_half_range,
    scale_span,
)
from .effects.backlash import slide_init, slide_step, stick_slip_step
from .effects.time_delay import delay_range, delay_shortlist, dominant_time_constant
from .residuals import feedback_test, noise_std_differences


DETERMINISTIC = (
    ParameterMismatch(),
    BacklashEffect(),
    DeadZoneEffect(),
    SaturationEffect(),
    PreloadEffect(),
    RateLimitEffect(),
    TimeDelayEffect(),
    ExtraPoleEffect(),
    OutputNonlinearityEffect(),
    FrictionEffect(),
    FeedbackNonlinearityEffect(),
)
BUCKETS = (256, 512, 1024, 1536, 2048, 3072, 4096, 6144, 8192, 12288, 16384)
# Records up to this length share one padded length per call (one compilation):
# the fits follow each record's own length (`fit.normal_equations`), so their
# padding costs memory, not time.
ONE_GROUP = 8192
N_MAX = 4
T_MAX = 64
MAX_EFFECT_SLOTS = 3  # most slots any one candidate row frees
# the highest order of the linear block `nominal_fit` selects, which a
# `REFIT_LINEAR` row re-fits whatever order was selected (the selection assumed
# a linear output map too)
FITTED_ORDER = 3
# the row (not a class) that re-fits the linear block as a `REFIT_LINEAR` row
# does, with the effect held neutral (its `level` slots free): the reference a
# `REFIT_LINEAR` row must beat to stand for its class (`best_row_per_class`)
LINEAR_TWIN = "linear_twin"
QUANTILES = (0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98)
# One unit of a scaled nominal parameter moves it by this fraction of its
# magnitude (slopes, gain, scales, denominator coefficients) or by half of it times
# the input range (breakpoints and levels of a piecewise-linear map).
RELATIVE_STEP = 0.1
LR_ALPHA = 1e-3  # level of the nested likelihood-ratio tests (before Bonferroni)
PRIOR_FLOOR = 1e-6  # the prior's weight without a stated uncertainty (a tie-break)
NOMINAL_UNCERTAINTY = 0.2  # default relative std of the nominal parameters
# The profile of the stick-slip play in (f_s, f_d) (`stick_slip_profile`): f_s as
# fractions of the input's range from 1 % (a valve that moves by less than a
# hundredth of its command's range is a play the plain starts already cover) to
# 50 % (beyond half the range the command never leaves the stick band after a
# reversal: no second slip), geometric with ratio 2**(1/64): in a closed loop the
# command crosses f_s by a hair before each slip (the loop reverses it once the
# valve moves), so a model with f_s 2 % above the truth misses slips and the SSE
# has a needle of that width in f_s; f_d / f_s geometric with ratio 2**(1/3) in
# (0.02, 0.9) (f_d = f_s: the plain play, a start of its own). Only for a record
# that looks closed-loop (`residuals.feedback_test` on the measured output, at
# its stated false-alarm rate): in open loop the command does not stop at the
# slip, the SSE is not a needle in f_s, and the plain starts serve as before.
STATIC_BAND_GRID = tuple(0.5 * 2.0 ** (-k / 64) for k in range(362))
KINETIC_RATIOS = tuple(0.9 * 2.0 ** (-k / 3) for k in range(17))
# the slot of each stick-slip variant's jump: He et al.'s slip, Choudhury et al.'s slide
VARIANTS = ("slip_jump", "slide_jump")
PROFILE_CHUNK = 512  # grid points simulated at once (memory: chunk x length)
PROFILE_STARTS = 2  # best grid points kept per variant (and map) of the profile
# the profile's starts of the backlash rows: the two best of the refined points
# (`REFINE_SPANS`) and the grid's second best as it is (`stick_slip_profile`)
PROFILE_POINTS = 3
# Beside a fitted nominal, passes of the profile's denominator re-fit (variable
# projection at the best point, then the grid again near it: `stick_slip_profile`)
# and the window of that local grid, in steps of `STATIC_BAND_GRID` either side
# (four times as wide on the first pass)
DENOMINATOR_PASSES = 2
LOCAL_STEPS = 16
DENOMINATOR_EVALUATIONS = 100  # residual evaluations of one variable-projection fit
# The profile's best points refined by coordinate search (`stick_slip_profile`):
# S, then J, each over `PROFILE_CHUNK` geometric steps within these factors either
# side, then the valve's start (`valve_start`) within START_REACH S (factor - 1) /
# (2**0.5 - 1) of it, a pass per factor (the first covers the grid's spacing in
# f_d, and starts up to past the band either side of v_0, where the valve slips at
# once)
REFINE_SPANS = (2.0**0.5, 2.0**0.125, 2.0 ** (1 / 32))
START_REACH = 1.1  # the start's first line reaches this many S either side
# beside an integrating nominal, the refinement on the record itself (after the
# differenced record's) with a first pass twice as wide: the differenced record
# places (S, J) more roughly (its noise is twice the record's, its signal a rate)
INTEGRATING_SPANS = (2.0, *REFINE_SPANS)
INTEGRATOR_TOLERANCE = 1e-6  # a pole this close to 1 is an integrator's
IDENTITY_PL = (1.0, 1.0, 0.0, 0.0, 0.0, 0.0)  # (k1, k2, d1, d2, l1, l2): F(v) = v


def prior_weight(uncertainty: float | None, noise_std: float) -> float:
    r"""Weight of the Gaussian prior at nominal on the scaled re-fit parameters.

    A user who states that each nominal parameter is uncertain by a relative
    standard deviation $u$ puts the prior $\theta_j \sim N(0, (u/\rho)^2)$ on
    its scaled deviation ($\rho$ = `RELATIVE_STEP`); with white output noise of
    std $\sigma$ in the fit's scaled units, the negative log posterior times
    $\sigma^2$ is $\sum_k r_k^2 + (\sigma\rho/u)^2 \sum_j \theta_j^2$, so the
    weight is $(\sigma\rho/u)^2$ (never below `PRIOR_FLOOR`; `uncertainty=None`:
    the floor alone). $\sigma$ is the median absolute second difference of the
    nominal's estimation residual (`residuals.noise_std_differences`): the upper
    band of that residual (`noise_floor_hf`) over-estimates it wherever the gap
    itself is broadband (a clip, a sign-blind sensor), which made the prior hold a
    re-fit far firmer than stated; the median is blind to a gap's few kinks and
    errs, under coloured noise, on the weak side (towards the plain fit)."""
    if uncertainty is None:
        return PRIOR_FLOOR
    if not (np.isfinite(uncertainty) and uncertainty > 0):
        raise ValueError(f"the nominal uncertainty must be > 0, got {uncertainty}")
    return max(PRIOR_FLOOR, (noise_std * RELATIVE_STEP / uncertainty) ** 2)


def _valve_step(slide: bool, width, jump):
    """The step `((x_prev, y, slide state), v_k) -> (v_k, y_k, state)` of the
    stick-slip play (`stick_slip_step`) or, for `slide`, Choudhury's valve
    (`slide_step`), elementwise over a grid of (S, J)."""

    def step(carry, vk):
        x_prev, y, ss = carry
        if slide:
            y, ss = slide_step(y, ss, x_prev, vk, width, jump)
        else:
            y = stick_slip_step(y, vk, width, jump)
        return vk, y, ss

    return step


def _valve_init(v0, width, start=None):
    """`_valve_step`'s carry at the start: at rest at $v_0$ plus `start` (each grid
    point's $\\delta$, `valve_start`; None: 0), as in the augmented model
    (`augmented.memory_init`)."""
    x0 = jnp.full(width.shape, v0) + (0.0 if start is None else start)
    return v0, x0, slide_init(x0)


@partial(jax.jit, static_argnames="slide")
def _valve_positions(
    v: Float[Array, " L"],
    width: Float[Array, " G"],
    jump: Float[Array, " G"],
    start: Float[Array, " G"] | None = None,
    *,
    slide: bool,
) -> Float[Array, "G L"]:
    """The valve positions of each (S, J) over `v` (`_valve_step`), started at
    $v_0$ + `start` (None: 0). One scan over time with the grid as its state's
    vector (three times faster than a scan per grid point under `vmap`)."""
    step = _valve_step(slide, width, jump)

    def body(carry, vk):
        carry = step(carry, vk)
        return carry, carry[1]

    return lax.scan(body, _valve_init(v[0], width, start), v)[1].T


PROFILE_BLOCK = 512  # time steps per call of `_profile_block`: one compilation


@partial(jax.jit, static_argnames=("slide", "mapped"))
def _profile_block(
    carry: tuple,
    v: Float[Array, " B"],
    y: Float[Array, " B"],
    mask: Float[Array, " B"],
    width: Float[Array, " G"],
    jump: Float[Array, " G"],
    a: Float[Array, " na1"],
    pl: Float[Array, " 6"],
    *,
    slide: bool,
    mapped: tuple[bool, ...],
) -> tuple:
    r"""`_profile_sums`' scan over one block of time steps from `carry` (the
    valve's carry, the filter's state `(na, M, G)`, the lagged inputs `(D, M,
    G)`, the sums $\sum u_k u_{k-j}$ `(D, M, G)`, $\sum y_k u_{k-j}$ `(D, M,
    G)` and $\sum u_k$ `(M, G)`, and the lagged inputs at the last unmasked
    step `(D, M, G)`); the carry after it."""
    step = _valve_step(slide, width, jump)
    zeros = jnp.zeros((len(mapped),) + width.shape)

    def body(carry, inputs):
        valve, z, w, lagged, rhs, total, last = carry
        vk, yk, mk = inputs
        valve = step(valve, vk)
        x = valve[1]
        u = jnp.stack(
            [piecewise_linear_map(x, *pl, xp=jnp) if m else x for m in mapped]
        )
        out = u + z[0]  # direct form II transposed, b = [1]
        z = jnp.concatenate([z[1:], zeros[None]]) - a[1:, None, None] * out[None]
        w = jnp.concatenate([out[None], w[:-1]])  # (depth, M, G): u_{k - i}
        return (
            valve,
            z,
            w,
            lagged + (mk * out)[None] * w,
            rhs + (mk * yk) * w,
            total + mk * out,
            jnp.where(mk > 0, w, last),
        ), None

    return lax.scan(body, carry, (v, y, mask))[0]


def _lagged_gram(
    lagged: np.ndarray, total: np.ndarray, last: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""The sums $G_{ij} = \sum_{k<n} u_{k-i} u_{k-j}$ `(D, D, ...)` and
    $T_i = \sum_{k<n} u_{k-i}$ `(D, ...)` from their first row
    $G_{0j}$ (`lagged`), $T_0$ (`total`) and the last lagged inputs
    $l_t = u_{n-1-t}$ (`last`, `(D, ...)`), with $u_k = 0$ for $k < 0$: a lag
    more on both sides drops the last product,
    $G_{i+1, j+1} = G_{ij} - l_i l_j$ and $T_{i+1} = T_i - l_i$, so
    $G_{ij} = G_{0, j-i} - \sum_{t<i} l_t l_{t+j-i}$ ($i \le j$)."""
    D = lagged.shape[0]
    gram = np.empty((D, D, *lagged.shape[1:]))
    for i in range(D):
        for j in range(i, D):
            d = j - i
            g = lagged[d] - np.sum(last[:i] * last[d : d + i], axis=0)
            gram[i, j] = gram[j, i] = g
    drop = np.concatenate([np.zeros_like(last[:1]), np.cumsum(last[:-1], axis=0)])
    return gram, total[None] - drop


def _profile_sums(
    v: np.ndarray,
    y: np.ndarray,
    width: np.ndarray,
    jump: np.ndarray,
    a: np.ndarray,
    pl: np.ndarray,
    *,
    slide: bool,
    mapped: tuple[bool, ...],
    depth: int,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""The lagged sums of the profile's least squares (`_free_numerator_sse`)
    for each (S, J) and each map of `mapped` (True: the nominal's
    piecewise-linear map `pl`, `piecewise_linear_map`; False: the identity),
    `(gram (M, G, D, D), rhs (M, G, D), total (M, G, D))`, $D$ = `depth`.

    One scan over time (`_profile_block`, `PROFILE_BLOCK` steps a call, the
    record padded to whole blocks) that never holds a grid x time array: the
    valve (`_valve_step`, at rest at $v_0$ + `start`), its input $u = F(x)$ filtered by
    $1/A$ ($a_0 = 1$, direct form II transposed from rest, as `lfilter_numpy`)
    and, with $w_i = u_{k-i}$ for the lags $i < D$ (zero before the start), the
    sums over the record of $w_i w_j$, $w_i y_k$ and $w_i$; of the first and
    the last only their first row, the rest from the record's last lagged
    inputs (`_lagged_gram`: $D$ products a step instead of $D^2$). As separate passes
    over a grid x time array the profile was memory-bound; this way it is
    compute-bound (and runs on every core: `diagnose_many`'s threads)."""
    n, B = v.shape[0], PROFILE_BLOCK
    total_len = -(-n // B) * B
    vp = np.concatenate([v, np.full(total_len - n, v[-1])])
    yp = np.concatenate([y, np.zeros(total_len - n)])
    mask = (np.arange(total_len) < n).astype(float)
    if a.shape[0] < 2:  # A = 1: one zero coefficient keeps the state's shape
        a = np.r_[a, 0.0]
    shape = (len(mapped), width.shape[0])
    carry = (  # as JAX arrays, as the blocks return it: one compilation
        _valve_init(
            jnp.asarray(v[0]), width, None if start is None else jnp.asarray(start)
        ),
        jnp.zeros((a.shape[0] - 1, *shape)),
        jnp.zeros((depth, *shape)),
        jnp.zeros((depth, *shape)),
        jnp.zeros((depth, *shape)),
        jnp.zeros(shape),
        jnp.zeros((depth, *shape)),
    )
    for k in range(0, total_len, B):
        carry = _profile_block(
            carry,
            vp[k : k + B],
            yp[k : k + B],
            mask[k : k + B],
            width,
            jump,
            a,
            pl,
            slide=slide,
            mapped=mapped,
        )
    lagged, rhs, total, last = (np.asarray(x) for x in carry[3:])
    gram, total = _lagged_gram(lagged, total, last)
    return (
        np.moveaxis(gram, (2, 3), (0, 1)),
        np.moveaxis(rhs, (1, 2), (0, 1)),
        np.moveaxis(total, (1, 2), (0, 1)),
    )


def stick_slip_profile(
    nom: "Nominal",
    linear,
    dt: float,
    v: np.ndarray,
    y: np.ndarray,
    length: int,
    *,
    refit_linear: bool = False,
) -> tuple[tuple[float, float, dict, str], ...]:
    r"""The `PROFILE_POINTS` starts $(S, J, \text{re-fit start}, \text{slot})$ of
    the backlash rows from the grid `STATIC_BAND_GRID` x `KINETIC_RATIOS` over
    both stick-slip variants (`VARIANTS`: the jump's slot; $S = f_s + f_d$, $J =
    f_s - f_d$ for both: the same reversal band $S$ and sliding offset $f_d = (S
    - J)/2$): the best two of the refined points (each variant's best grid
    point, refined as below; beside an integrating nominal a second basin's
    too), best first, then the grid's second best point as it is.

    Each grid point is scored by separable least squares (Jelali 2008, valve
    stiction by a global search over the stiction parameters with the linear
    model fitted by least squares at each point): the estimation SSE of $y
    \approx \sum_j b_j q^{-j} F(x(S, J)) / A(q)$, the nominal's denominator $A$
    and map $F$ with a free numerator (`_numerator_lags`), linear in $b$. The
    nominal's own numerator is not kept: beside a linear nominal fitted on the
    sticky record itself (no model.json) it has absorbed the valve (the play's
    lag looks like a slower, smaller response), and scored with it the true
    $(S, J)$ of a sticky loop lost to a narrower band (measured on the
    control-loop benchmark). With a piecewise-linear map (which a fitted nominal
    picks up from the valve too: a dead band looks like one) the identity map is
    scored as well.

    Beside hamjax's own discrete nominal (`refit_linear`, as
    `StartContext.refit_linear`) its denominator is no better than its numerator
    (poles fitted to a valve's limit cycle: a mode near $-1$, a near-integrator),
    so the denominator is re-fitted too, by variable projection at the best point
    (`_refit_denominator`: the output error over $A$, $b$ by least squares), at
    the order the row re-fits (`refit_linear_order`; from the nominal's $A$
    padded with zeros: a sticky record's own nominal is often of lower order
    than the process, the selection having seen the valve's limit cycle), and
    the grid scored again with it near that point's $f_s$, within four times
    `LOCAL_STEPS` (a factor of 2 either way: a wrong $A$ moved the best $f_s$ by
    a quarter in the tests), then within `LOCAL_STEPS`; up to
    `DENOMINATOR_PASSES` times while the best SSE falls, with the best point's
    map. There the re-fit
    start re-fits the whole linear block (`REFIT_LINEAR`) from the fitted $A$ and
    numerator (its changes `db..`, up to the lag a re-fit moves:
    `refit_linear_order`) with an output level $c$, fitted with them (slot
    `out_off`, a level beside the effect: `BacklashEffect.level`; where the
    record is a slice of a loop's operation, an integrating process's output
    starts where its level was, not at rest), and a point scored with the
    identity map holds the map at the identity there (`IDENTITY_MAP`: the
    row's `held` map slots; before, its start freed the map's slots and kept the
    nominal's $A$, not the profile's, and an integrating loop's row fitted the
    valve it found with the poles of a nominal that had lost its integrator);
    otherwise it is the gain
    $\sum b / \sum b_{nom}$ (both over the same $A$: the ratio of static
    gains; `{"gain": g}`); for the identity map `{"k1": g, "k2": g, "d1": 0,
    ...}` (the map's slots, which a re-fit frees, carry it).

    Each chunk of `PROFILE_CHUNK` grid points is scored in one scan over time
    (`_profile_sums`: the valve, the map, $1/A$ and the lagged sums), the
    normal equations solved on the host (`_solve_lagged`).

    The exact steps' instants of slip move only with $f_s$ (and $J$), where the
    fit has no derivative; this search places them (and $f_d$ near its value)
    before the Levenberg-Marquardt fit, which then moves $f_d$ and the re-fit.
    In a closed loop the SSE is a needle in $S$ and in $J$ both (the command
    stops by a hair past each slip), narrower than the grid's steps in $f_d$:
    each variant's best point is refined by coordinate search, a line in $S$,
    one in $J$ and one in the valve's start $\delta$ (`valve_start`: where the
    record finds the valve stuck, which the start returns; the grid has it at
    0, centred at $v_0$), each of `PROFILE_CHUNK` points, on ever finer spans
    (`REFINE_SPANS`; on the control-loop benchmark's seed 2, case 75, the best
    point's estimation RMS fell from 0.137 to 0.075, the true valve's 0.077
    under the same $A$).

    Beside a nominal with an integrator (a pole at 1 within
    `INTEGRATOR_TOLERANCE`: a level loop, a position) a valve stuck off $v_0$
    at the start drives a ramp until its first slip, and the SSE is a needle
    in $\delta$ too (a hundredth of the band wide): scored at $\delta = 0$ the
    grid may rank the truth far down. There a second basin is searched: the
    grid, the denominator's re-fit and the refinement in $S$ and $J$ on the
    differenced record $\Delta y$ through $A / (1 - q^{-1})$, where that start
    leaves a level only until the first slip, each variant's point then
    refined on the record itself with $A$, the start first
    (`INTEGRATING_SPANS`); the two best refined points of both basins, by the
    record's SSE, are the first two starts. (The differenced record alone,
    whose noise is twice the record's and whose signal is a rate, lost loops
    whose band the record's grid had found.)
    `length`: the padded record length (one compilation per length)."""
    n = v.shape[0]
    vr = float(max(np.ptp(v), 1e-12))
    fs = np.repeat(np.asarray(STATIC_BAND_GRID) * vr, len(KINETIC_RATIOS))
    fd = fs * np.tile(np.asarray(KINETIC_RATIOS), len(STATIC_BAND_GRID))
    vp = np.concatenate([v, np.full(length - n, v[-1])])
    b_nom, a_nom = _discrete_tf(linear, dt)
    last = refit_linear_order(nom) if refit_linear else b_nom.shape[0] + 1
    lags = _numerator_lags(b_nom, last)
    maps = [True] + ([False] if nom.nl_kind == NL_PIECEWISE else [])
    # the maps a scan evaluates itself (`_profile_sums`); a tabulated map or
    # one with memory goes through the valve positions on the host
    fused = nom.nl_kind in (NL_IDENTITY, NL_PIECEWISE)

    def padded(x):  # G <= PROFILE_CHUNK grid points padded to it: one shape
        return np.pad(x, (0, PROFILE_CHUNK - x.shape[0]), mode="edge")

    def valves(S, J, slot, d=None):  # (G, n)
        d = np.zeros(S.shape[0]) if d is None else d
        x = _valve_positions(
            vp, padded(S), padded(J), padded(d), slide=slot == "slide_jump"
        )
        return np.asarray(x)[: S.shape[0], :n]

    def mapped_input(x):  # F(x) of each grid point's valve positions, (G, n)
        if nom.nl_kind == NL_IDENTITY:
            return x
        if nom.nl_kind == NL_BACKLASH:  # a map with memory: row by row
            return np.stack([_static_numpy(nom, xi) for xi in x])
        return _static_numpy(nom, x)  # elementwise: every row at once

    def sums(a, t, S, J, slot, maps, d=None):  # SSE (a non-finite one inf), numerator
        d = np.zeros(S.shape[0]) if d is None else d  # `t`: the target output
        sse = {m: np.empty(S.shape[0]) for m in maps}
        width = lags.shape[0] + int(refit_linear)
        b = {m: np.empty((S.shape[0], width)) for m in maps}
        for i in range(0, S.shape[0], PROFILE_CHUNK):
            c = slice(i, i + PROFILE_CHUNK)
            if fused:  # both maps in one scan (`_profile_sums`)
                gram, rhs, total = _profile_sums(
                    v,
                    t,
                    padded(S[c]),
                    padded(J[c]),
                    a,
                    nom.pl,
                    slide=slot == "slide_jump",
                    mapped=tuple(m and nom.nl_kind == NL_PIECEWISE for m in maps),
                    depth=int(lags[-1]) + 1,
                    start=padded(d[c]),
                )
                k = S[c].shape[0]
                gram, rhs, total = (g[:, :k] for g in (gram, rhs, total))
                for j, m in enumerate(maps):
                    sse[m][c], b[m][c] = _solve_lagged(
                        gram[j], rhs[j], total[j], t, lags, level=refit_linear
                    )
                continue
            x = valves(S[c], J[c], slot, d[c])
            for m in maps:  # the valve positions once for both maps
                u = lfilter_numpy(_ONE, a, mapped_input(x) if m else x)
                sse[m][c], b[m][c] = _free_numerator_sse(u, t, lags, level=refit_linear)
        return {m: np.where(np.isfinite(e), e, np.inf) for m, e in sse.items()}, b

    def score(a, t, fs, fd, maps):  # the best points of each variant and map
        found = []
        for slot in VARIANTS:
            sse, b = sums(a, t, fs + fd, fs - fd, slot, maps)
            for m in maps:
                e = sse[m]
                best = np.argsort(e, kind="stable")[:PROFILE_STARTS]
                found += [
                    (e[i], fs[i] + fd[i], fs[i] - fd[i], b[m][i], m, slot, 0.0)
                    for i in best
                ]
        found.sort(key=lambda f: f[0])  # stable: the He variant first on ties
        return found

    def refine(a, t, point, lines, spans=REFINE_SPANS):  # on finer lines
        e, S, J, b, m, slot, d = point
        one = np.ones(PROFILE_CHUNK)
        for span in spans:
            g = np.exp(np.linspace(-np.log(span), np.log(span), PROFILE_CHUNK))
            # the start's line: within START_REACH S of it on the first pass,
            # then narrower as the others
            h = np.linspace(-1.0, 1.0, PROFILE_CHUNK) * (span - 1.0)
            h = START_REACH * h / (REFINE_SPANS[0] - 1.0)
            for line in lines:
                SS = S * g if line == "S" else S * one
                JJ = np.minimum(J * g if line == "J" else J * one, SS)  # f_d >= 0
                dd = d + S * h if line == "start" else d * one
                sse, bb = sums(a, t, SS, JJ, slot, [m], dd)
                i = int(np.argmin(sse[m]))
                if sse[m][i] < e:
                    e, S, J, d, b = sse[m][i], SS[i], JJ[i], dd[i], bb[m][i]
        return e, S, J, b, m, slot, d

    def rescored(a, t, point):  # the point's SSE and numerator on `t`
        _, S, J, _, m, slot, d = point
        sse, b = sums(a, t, np.array([S]), np.array([J]), slot, [m], np.array([d]))
        return sse[m][0], S, J, b[m][0], m, slot, d

    def search(a, t, lines, order):  # the grid, the denominator's re-fit, refinement
        found = score(a, t, fs, fd, maps)
        for k in range(DENOMINATOR_PASSES if refit_linear else 0):
            sse0, S0, J0, _, mapped, slot0, _ = found[0]
            x = valves(np.array([S0]), np.array([J0]), slot0)
            u = (mapped_input(x) if mapped else x)[0]
            # at the order the row re-fits (`refit_linear_order`): the
            # nominal's A with zeros beyond its own order to start from
            a_new = _refit_denominator(
                u, t, np.pad(a, (0, max(order + 1 - a.shape[0], 0))), lags, level=True
            )
            if a_new is None:
                break
            f0 = (S0 + J0) / 2
            steps = LOCAL_STEPS * (4 if k == 0 else 1)  # the first: A moved f_s
            near = np.abs(np.log(fs / f0)) <= (steps + 0.5) * np.log(2.0) / 64
            again = score(a_new, t, fs[near], fd[near], [mapped])
            if not again[0][0] < sse0:
                break
            a, found = a_new, again
        # each variant's best point (with the best point's map) refined: both
        # variants' needles are narrower than the grid's steps in f_d
        first = [
            next(f for f in found if f[5] == s and f[4] == found[0][4])
            for s in VARIANTS
        ]
        return a, [refine(a, t, f, lines) for f in first], found[1]

    a, refined, second = search(a_nom, y, ("S", "J", "start"), last)
    points = [(f, a) for f in refined]
    integrating = (
        integrators(
            DiscreteTransferFunction(b_nom, a_nom, dt), tolerance=INTEGRATOR_TOLERANCE
        )
        > 0
    )
    if integrating:  # the differenced record's basin beside the record's
        a_d, refined_d, _ = search(
            np.polydiv(a_nom, [1.0, -1.0])[0],
            np.r_[y[0], np.diff(y)],
            ("S", "J"),
            last - 1,  # the integrator is the row's last order
        )
        a_d = np.convolve(a_d, [1.0, -1.0])
        points += [
            (
                refine(
                    a_d, y, rescored(a_d, y, f), ("start", "S", "J"), INTEGRATING_SPANS
                ),
                a_d,
            )
            for f in refined_d
        ]
    # the best refined points, then the grid's second best as it is (a refined
    # pair may meet at one point)
    points = sorted(points, key=lambda p: p[0][0])[: PROFILE_POINTS - 1]
    points.append((second, a))
    return tuple(
        (
            float(S),
            float(J),
            {
                **_refit_start(b, b_nom, a, lags, mapped, refit_linear),
                "valve_start": float(d),
            },
            slot,
        )
        for (_, S, J, b, mapped, slot, d), a in points
    )


def _refit_denominator(
    u: np.ndarray, y: np.ndarray, a0: np.ndarray, lags: np.ndarray, *, level=False
) -> np.ndarray | None:
    r"""The denominator $A$ (`a[0] = 1`, the order of `a0`) minimising the output
    error $\|y - \sum_j b_j q^{-l_j} u / A\|^2$ with $b$ at its least squares for
    each $A$ (variable projection: Golub & Pereyra 1973; `_free_numerator_sse`,
    with the constant $c$ where `level`), Levenberg-Marquardt from `a0`
    (`scipy.optimize.least_squares`, at most `DENOMINATOR_EVALUATIONS`
    residuals). None when it fails, does not lower the
    error by more than rounding, or leaves a pole outside the unit circle (an
    integrator's at 1 may stay)."""
    from scipy.optimize import least_squares

    @np.errstate(over="ignore", invalid="ignore")  # a trial A may be unstable
    def residual(tail):
        a = np.r_[1.0, tail]
        w = lfilter_numpy(_ONE, a, u[None, :])
        _, b = _free_numerator_sse(w, y, lags, level=level)
        full = np.zeros(int(lags[-1]) + 1)
        full[lags] = b[0, : lags.shape[0]]
        out = y - lfilter_numpy(full, a, u[None, :])[0] - (b[0, -1] if level else 0.0)
        return np.where(np.isfinite(out), out, 1e150)

    if a0.shape[0] < 2:
        return None
    r0 = residual(a0[1:])
    try:
        fit = least_squares(
            residual, a0[1:], method="lm", max_nfev=DENOMINATOR_EVALUATIONS
        )
    except (ValueError, np.linalg.LinAlgError):
        return None
    a = np.r_[1.0, fit.x]
    stable = np.all(np.abs(np.roots(a)) <= 1.0 + 1e-9)
    # lower by more than rounding: the sums of squares are computed to about
    # machine epsilon times the record's energy (at an exact optimum both are
    # rounding, and either may be the smaller)
    rounding = np.finfo(float).eps * float(np.sum(y**2))
    if not (stable and np.sum(fit.fun**2) < np.sum(r0**2) - rounding):
        return None
    return a


_ONE = np.ones(1)


def _refit_start(
    b: np.ndarray,
    b_nom: np.ndarray,
    a: np.ndarray,
    lags: np.ndarray,
    mapped: bool,
    linear: bool,
) -> dict[str, float]:
    """The re-fit's start of a profile point of fitted numerator `b` (at `lags`)
    over the denominator `a` (`stick_slip_profile`): in a `REFIT_LINEAR` row
    (`linear`) that denominator, the numerator's changes from the nominal's
    `b_nom` and the output level (`b`'s last entry, `_free_numerator_sse`'s
    constant, slot `out_off`), with the map held at the identity where the point
    was scored without the nominal's piecewise-linear map (not `mapped`:
    `IDENTITY_MAP`); otherwise the ratio of the static gains, or where the point
    was scored without that map, the map at the gain times the identity."""
    total = float(np.sum(b_nom))
    g = float(np.sum(b[: lags.shape[0]])) / total if total != 0 else 1.0
    if not linear:
        if not mapped:
            return {"k1": g, "k2": g, "d1": 0.0, "d2": 0.0, "l1": 0.0, "l2": 0.0}
        return {"gain": g}
    nom = np.zeros(int(lags[-1]) + 1)
    k = min(b_nom.shape[0], nom.shape[0])
    nom[:k] = b_nom[:k]
    db = {f"db{j}": float(b[i] - nom[j]) for i, j in enumerate(lags)}
    den = {f"den{j}": float(a[j]) for j in range(1, a.shape[0])}
    identity = {} if mapped else {IDENTITY_MAP: 1.0}
    return {REFIT_LINEAR: 1.0, **identity, **den, **db, "out_off": float(b[-1])}


def identity_twin_start(
    nom: "Nominal", linear, dt: float, v: np.ndarray, y: np.ndarray, dens: list
) -> dict[str, float]:
    r"""The start of the `LINEAR_TWIN` that holds a piecewise-linear map at the
    identity (`IDENTITY_MAP`): the linear block of the order a `REFIT_LINEAR`
    row re-fits, fitted to `y` from `v` itself (no valve) by variable projection
    (`_refit_denominator`, with the output level) from the nominal's $A$ and from
    each denominator of `dens` (the profile's identity-map points), the best of
    them by the estimation SSE, as `_refit_start` gives it.

    The twin must start as close to its optimum as the rows it is the reference
    of: from the nominal's numerator and poles (a nominal that took the valve's
    dead band into its map and lost an integrating loop's integrator), its fit
    stopped far above the noise floor on integrating loops without stiction,
    and the play's rows, started from the profile's fit, beat it by a wide
    likelihood ratio (four such loops of seeds 1-7 of the control-loop
    benchmark, measured)."""
    b_nom, a_nom = _discrete_tf(linear, dt)
    order = refit_linear_order(nom)
    lags = _numerator_lags(b_nom, order)
    best = (np.inf, None, None)
    for a0 in [a_nom, *dens]:
        a0 = np.pad(a0, (0, max(order + 1 - a0.shape[0], 0)))[: order + 1]
        a = _refit_denominator(v, y, a0, lags, level=True)
        a = a0 if a is None else a
        with np.errstate(over="ignore", invalid="ignore"):
            sse, b = _free_numerator_sse(
                lfilter_numpy(_ONE, a, v[None, :]), y, lags, level=True
            )
        if np.isfinite(sse[0]) and sse[0] < best[0]:
            best = (sse[0], b[0], a)
    if best[1] is None:
        return {}
    return _refit_start(best[1], b_nom, best[2], lags, False, True)


def refit_linear_order(nom: "Nominal") -> int:
    """The order of the linear block a `REFIT_LINEAR` row re-fits beside hamjax's
    own discrete nominal: its numerator's changes `db..` reach this lag."""
    return max(FITTED_ORDER, nom.den.shape[0] - 1, nom.b.shape[0] - 1)


def _discrete_tf(linear, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """`(b, a)` of the linear block in discrete time (a continuous one by zero-order
    hold), `a[0] = 1`."""
    from scipy import signal

    if isinstance(linear, ContinuousTransferFunction):
        ss = zoh_tf(np.asarray(linear.num), np.asarray(linear.den), dt, xp=np)
        b, a = signal.ss2tf(*ss)
        b, a = np.asarray(b[0], float), np.asarray(a, float)
    else:
        b, a = np.asarray(linear.b, float), np.asarray(linear.a, float)
    return b / a[0], a / a[0]


def _numerator_lags(b: np.ndarray, last: int) -> np.ndarray:
    """The lags of the profile's free numerator: from the nominal's first nonzero
    coefficient (its delay: `nominal_fit` gives a closed-loop record $b_0 = 0$,
    which keeps the controller's reaction to the current noise out of the fit) to
    `last`."""
    nz = np.flatnonzero(b)
    first = int(nz[0]) if nz.size else 0
    return np.arange(first, max(last, first) + 1)


def _free_numerator_sse(
    u: np.ndarray, y: np.ndarray, lags: np.ndarray, *, level: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """For each row of `u` (`(G, n)`: the input filtered by $1/A$), the least-squares
    fit of `y` by $\\sum_j b_j u_{k - l_j}$ ($l_j$: `lags`, ascending, from rest),
    plus a constant $c$ where `level`: `(sse (G,), coefficients (G, lags [+ 1]))`,
    $c$ last.

    The normal equations from lagged products: $\\sum_k u_{k-a} u_{k-b}$ ($a \\le
    b$) is the full product at lag $b - a$ less its last $a$ terms, so each lag
    difference costs one pass over the rows, and the SSE is $y^T y - \\theta^T
    (X^T y)$ at the solution."""
    return _solve_lagged(*_lagged_sums(u, y, lags), y, lags, level=level)


def _lagged_sums(
    u: np.ndarray, y: np.ndarray, lags: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`_profile_sums`' sums on the host, from the rows of `u` (`(G, n)`), at the
    entries of `lags` (the others 0): `(gram (G, D, D), rhs (G, D), total (G, D))`,
    $D$ = `lags[-1] + 1`."""
    n, G, D = y.shape[0], u.shape[0], int(lags[-1]) + 1
    shifted = np.zeros((n, lags.shape[0]))  # y_{k + l_j}: U^T y as one product
    for j, lag in enumerate(lags):
        shifted[: n - lag, j] = y[lag:]
    rhs, total = np.zeros((G, D)), np.zeros((G, D))
    rhs[:, lags] = u @ shifted
    full = {
        int(d): np.einsum("gk,gk->g", u[:, d:], u[:, : n - d])
        for d in np.unique(lags[None, :] - lags[:, None])
        if d >= 0
    }
    gram = np.zeros((G, D, D))
    for i, a in enumerate(lags):
        for b in lags[i:]:
            m = full[int(b - a)]
            if a > 0:  # the terms past the record's end for the later lag
                m = m - np.einsum("gk,gk->g", u[:, n - a :], u[:, n - b : n - b + a])
            gram[:, a, b] = gram[:, b, a] = m
        total[:, a] = np.sum(u[:, : n - a], axis=1)
    return gram, rhs, total


def _solve_lagged(
    gram: np.ndarray,
    rhs: np.ndarray,
    total: np.ndarray,
    y: np.ndarray,
    lags: np.ndarray,
    *,
    level: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """`_free_numerator_sse` from the sums over the lags $0 .. D - 1$ (`(G, D,
    D)`, `(G, D)`, `(G, D)`) of the rows' filtered inputs (`_profile_sums`, or
    `_lagged_sums` on the host): those of `lags`, with the constant where
    `level`."""
    p = lags.shape[0]
    q = p + int(level)
    g = np.empty((gram.shape[0], q, q))
    g[:, :p, :p] = gram[:, lags][:, :, lags]
    r = [rhs[:, lags]]
    if level:
        g[:, :p, p] = g[:, p, :p] = total[:, lags]
        g[:, p, p] = y.shape[0]
        r.append(np.full((gram.shape[0], 1), np.sum(y)))
    rhs = np.concatenate(r, axis=1)
    # a relative ridge of 1e-12 against a singular gram
    ridge = 1e-12 * np.maximum(np.trace(g, axis1=1, axis2=2), 1e-300) / q
    coef = np.linalg.solve(g + ridge[:, None, None] * np.eye(q), rhs[..., None])
    coef = coef[..., 0]
    return np.maximum(y @ y - np.einsum("gp,gp->g", coef, rhs), 0.0), coef


def looks_closed_loop(y: np.ndarray, v: np.ndarray) -> bool:
    """`residuals.feedback_test` of the measured output `y` against `v` (False
    where it does not apply: a periodic input, a short record). The output, not
    the nominal's residual: the test's level must not depend on the nominal
    being right, and the nominal's numerator may have a direct feedthrough."""
    return bool(feedback_test(y, v).get("closed_loop", False))


def bucket(n: int) -> int:
    """Smallest padded record length >= n (few lengths: few compilations)."""
    for b in BUCKETS:
        if n <= b:
            return b
    return int(np.ceil(n / 4096) * 4096)


@dataclass(frozen=True)
class Nominal:
    """The re-fittable description of a nominal plant."""

    nl_kind: int
    pl: np.ndarray  # k1 k2 d1 d2 l1 l2
    tab_v: np.ndarray
    tab_u: np.ndarray  # the map, or a backlash's ascending border
    tab_d: np.ndarray  # a backlash's descending border (else `tab_u`)
    is_ct: bool
    b: np.ndarray  # discrete numerator / continuous numerator (highest power first)
    den: np.ndarray  # discrete a (a[0] = 1) / continuous den (highest power first)
    order: int


def _tables(nl, tab_v: np.ndarray, tab_u: np.ndarray, tab_d: np.ndarray | None):
    if tab_v.shape[0] > T_MAX:
        raise ValueError(
            f"{type(nl).__name__} map has {tab_v.shape[0]} points (at most {T_MAX})"
        )
    return tab_v, tab_u, tab_u if tab_d is None else tab_d


def _backlash_tables(nl: Backlash):
    """The borders of a backlash tabulated on one grid, centred in the play at
    the start (the `model.json` form and convention), else `ValueError`."""
    asc, desc = nl.ascending, nl.descending
    if not (
        isinstance(asc, Tabulated)
        and isinstance(desc, Tabulated)
        and np.array_equal(np.asarray(asc.v), np.asarray(desc.v))
    ):
        raise ValueError(
            "a backlash nominal needs both borders tabulated on one grid (the "
            "model.json form)"
        )
    if nl.u0 is not None:
        raise ValueError(
            "a backlash nominal starts centred in its play (u0 = None, the "
            "model.json convention)"
        )
    grid = np.asarray(asc.v, float)
    return _tables(nl, grid, np.asarray(asc.u, float), np.asarray(desc.u, float))


def describe_nominal(plant: Hammerstein) -> Nominal:
    """Read the parameters the diagnosis may re-fit off a nominal plant (a
    backlash nominal's output scale folded into its linear block first:
    `fold_output_scale`).

    **Raises:** `ValueError` for a nonlinearity or linear block outside the
    `model.json` kinds handled by the diagnosis, or an order above `N_MAX`.
    """
    plant = fold_output_scale(plant)
    nl, lin = plant.nonlinearity, plant.linear
    pl = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    tab_v, tab_u = np.array([-1.0, 1.0]), np.array([-1.0, 1.0])
    tab_d = tab_u
    if isinstance(nl, Identity):
        kind = NL_IDENTITY
    elif isinstance(nl, PiecewiseLinear):
        kind = NL_PIECEWISE
        pl = np.array([float(getattr(nl, k)) for k in PL_PARAMETERS])
    elif isinstance(nl, Tabulated):
        kind = NL_TABULATED
        tab_v, tab_u, tab_d = _tables(
            nl, np.asarray(nl.v, float), np.asarray(nl.u, float), None
        )
    elif isinstance(nl, Backlash):
        kind = NL_BACKLASH
        tab_v, tab_u, tab_d = _backlash_tables(nl)
    else:
        raise ValueError(
            "the diagnosis handles identity, piecewise_linear, tabulated and "
            f"backlash maps; got {type(nl).__name__}"
        )
    if isinstance(lin, DiscreteTransferFunction):
        b, den, ct = np.asarray(lin.b, float), np.asarray(lin.a, float), False
        order = max(b.shape[0], den.shape[0]) - 1
    elif isinstance(lin, ContinuousTransferFunction):
        b, den, ct = np.asarray(lin.num, float), np.asarray(lin.den, float), True
        order = den.shape[0] - 1
    else:
        raise ValueError(f"unsupported linear block {type(lin).__name__}")
    if order > N_MAX:
        raise ValueError(
            f"linear block of order {order} (the diagnosis handles <= {N_MAX})"
        )
    if order < 1:
        raise ValueError("the linear block must have at least one pole")
    return Nominal(kind, pl, tab_v, tab_u, tab_d, ct, b, den, order)


def _pad_table(v: np.ndarray, *us: np.ndarray) -> tuple[np.ndarray, ...]:
    """`v` and each table `us` padded to `T_MAX` points (constant beyond `v[-1]`,
    as `np.interp` extrapolates)."""
    extra = T_MAX - v.shape[0]
    step = max(abs(v[-1]) + abs(v[0]), 1.0) * 1e6
    return (
        np.concatenate([v, v[-1] + step * np.arange(1, extra + 1)]),
        *(np.concatenate([u, np.full(extra, u[-1])]) for u in us),
    )


def _pad_record(x: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    n = x.shape[0]
    pad = np.full(length - n, x[-1])
    return np.concatenate([x, pad]), np.concatenate([np.ones(n), np.zeros(length - n)])


def _linear_templates(nom: Nominal, dt: float):
    n1 = N_MAX + 1
    b_disc, ct_num, ct_pad = np.zeros(n1), np.zeros(n1), np.zeros(n1)
    ct_pad[-1] = 1.0
    den_slots, den_lead = np.zeros(N_MAX), 1.0
    if not nom.is_ct:
        b_disc[: nom.b.shape[0]] = nom.b
        den_slots[: nom.den.shape[0] - 1] = nom.den[1:]
        free = list(range(nom.den.shape[0] - 1))
        ct_num[-1] = 0.0
        return b_disc, ct_num, ct_pad, den_slots, den_lead, free
    n = nom.order
    den = nom.den / nom.den[0]
    num = nom.b / nom.den[0]
    lam = 1.0 / dt
    pad = np.poly(-lam * np.ones(N_MAX - n)) if n < N_MAX else np.ones(1)
    ct_pad[-pad.shape[0] :] = pad
    full_num = np.convolve(num, pad)
    ct_num[-full_num.shape[0] :] = full_num
    den_pad = np.zeros(n1)
    den_pad[-(n + 1) :] = den
    den_slots, den_lead = den_pad[1:], den_pad[0]
    free = list(range(N_MAX - n, N_MAX))
    return b_disc, ct_num, ct_pad, den_slots, float(den_lead), free


@dataclass(frozen=True)
class Prepared:
    """A case ready for the batched fit."""

    arrays: CaseArrays
    rows: list  # list of (class name, Row)
    ctx: StartContext
    nominal: Nominal
    n_est: int
    n_val: int
    w_est: np.ndarray  # nominal output on the estimation record
    w_val: np.ndarray
    u_val: np.ndarray  # nominal u = F(v) on validation
    # the nominal is hamjax's own fit (no model.json): a re-fit of it is no
    # verdict, and the reference where it improves on it (`attribute.reference`)
    fitted: bool = False
    # the estimation record looks closed-loop (`looks_closed_loop`); None: not
    # tested (`prepare(screens=False)`)
    closed_loop: bool | None = None


def prepare(
    plant: Hammerstein,
    dt: float,
    est: dict,
    val: dict,
    length: int | None = None,
    n_params: int | None = None,
    *,
    nominal_uncertainty: float | None = None,
    fitted_nominal: bool = False,
    screens: bool = True,
) -> Prepared:
    """Case arrays and candidate rows for `plant` and the two records (`t,v,y` dicts).

    `nominal_uncertainty`: the relative std of the nominal parameters, the prior
    of every re-fit (`prior_weight`); None for a negligible prior.
    `fitted_nominal`: `plant` is hamjax's own fit (`nominal_fit`, no model.json),
    so starts that re-fit its whole discrete linear block are offered
    (`REFIT_LINEAR`; `n_free_parameters(..., fitted=True)` wide).
    `screens=False` skips the two searches that only place other rows' starts:
    the stick-slip profile of a closed-loop record (the backlash rows then start
    from their plain starts only) and the delay screen (`delay_shortlist`; the
    time-delay rows then try the whole part 0 only): for a caller that fits the
    re-fit row alone (`nominal_fit`), which neither screen changes."""
    plant = fold_output_scale(plant)
    nom = describe_nominal(plant)
    n_est, n_val = est["v"].shape[0], val["v"].shape[0]
    L = length or bucket(max(n_est, n_val))
    u_est = np.asarray(_static_numpy(nom, est["v"]))
    u_val = np.asarray(_static_numpy(nom, val["v"]))
    # the responses to the two records and to the unit step (`delay_shortlist`)
    # in one call, each padded at its end (from rest: causal)
    n_most = max(n_est, n_val)
    w_est, w_val, step_est = _response_numpy(
        plant.linear,
        np.stack(
            [
                np.pad(x, (0, n_most - x.shape[0]))
                for x in (u_est, u_val, np.ones(n_est))
            ]
        ),
        dt,
    )
    w_est, w_val, step_est = w_est[:n_est], w_val[:n_val], step_est[:n_est]
    v = est["v"]
    # the estimation record looks closed-loop (the stick-slip profile's screen,
    # and `attribute`'s residual-input test, which does not apply there)
    closed = looks_closed_loop(np.asarray(est["y"]), np.asarray(v)) if screens else None
    dw = np.diff(w_est) / dt if n_est > 1 else np.zeros(1)
    t_dom = dominant_time_constant(nom.den, nom.is_ct, dt)
    ctx = StartContext(
        v_min=float(v.min()),
        v_max=float(v.max()),
        v_absmax=float(np.abs(v).max()),
        max_step=float(max(np.abs(np.diff(v)).max(), 1e-12)),
        dt=float(dt),
        u_quantiles={
            q: float(x)
            for q, x in zip(QUANTILES, np.quantile(u_est, QUANTILES), strict=False)
        },
        u_std=float(max(u_est.std(), 1e-12)),
        w_quantiles={
            q: float(x)
            for q, x in zip(QUANTILES, np.quantile(w_est, QUANTILES), strict=False)
        },
        dw_half=float(
            max(abs(np.quantile(dw, 0.98)), abs(np.quantile(dw, 0.02)), 1e-12)
        ),
        stick_slip=stick_slip_profile(
            nom,
            plant.linear,
            dt,
            np.asarray(v),
            np.asarray(est["y"]),
            L,
            refit_linear=bool(fitted_nominal and not nom.is_ct),
        )
        if closed
        else (),
        t_dom=float(t_dom),
        refit_linear=bool(fitted_nominal and not nom.is_ct),
    )
    b_disc, ct_num, ct_pad, den_slots, den_lead, den_free = _linear_templates(nom, dt)
    names = slot_names(N_MAX)
    S = len(names)
    anchor, scale, neutral = np.zeros(S), np.ones(S), np.zeros(S)
    nominal_values = dict(zip(PL_PARAMETERS, nom.pl, strict=False))
    nominal_values.update(in_scale=1.0, out_scale=1.0, gain=1.0)
    span = scale_span(ctx)
    for i, name in enumerate(NOMINAL_SLOTS):
        val_ = nominal_values[name]
        anchor[i] = neutral[i] = val_
        if name in ("k1", "k2"):
            scale[i] = RELATIVE_STEP * max(abs(val_), 0.1)
        elif name in ("d1", "d2", "l1", "l2"):
            scale[i] = 0.5 * RELATIVE_STEP * span
        else:
            scale[i] = RELATIVE_STEP
    den_scale = RELATIVE_STEP * max(np.abs(den_slots).max(), 1e-6)
    for j in range(N_MAX):
        i = len(NOMINAL_SLOTS) + len(EFFECT_SLOTS) + j
        anchor[i] = neutral[i] = den_slots[j]
        scale[i] = RELATIVE_STEP * max(abs(den_slots[j]), den_scale)
    db_scale = RELATIVE_STEP * max(np.abs(b_disc).max(), 1e-12)
    for name in numerator_slots(N_MAX):
        scale[names.index(name)] = db_scale  # anchor and neutral 0: b as nominal
    w_half = output_half_range(ctx)
    w_centre = 0.0  # bend about w = 0 (a sensor's zero): a pure quadratic stays exact
    effect_scale = effect_scales(ctx)
    for name in EFFECT_SLOTS:
        i = names.index(name)
        neutral[i] = EFFECT_NEUTRAL[name]
        scale[i] = effect_scale[name]
    refit = [f"den{j + 1}" for j in den_free]
    if nom.nl_kind == NL_PIECEWISE:
        refit += list(PL_PARAMETERS)
    elif nom.nl_kind in (NL_TABULATED, NL_BACKLASH):
        refit += ["in_scale", "out_scale"]
    else:
        # With a piecewise-linear or tabulated map the static gain is not a
        # separate parameter: G's gain times F is F with its slopes and levels (or
        # its output scale) scaled, so re-fitting both leaves an exact ridge along
        # which the fit wanders and Levenberg-Marquardt crawls.
        refit = ["gain", *refit]
    # a `REFIT_LINEAR` start: numerator and denominator of the highest fitted
    # order, the gain (which the numerator carries) and the map held at nominal;
    # the nominal's delay, its numerator's leading zeros, stays (`nominal_fit`
    # gives a closed-loop record b0 = 0, the delay that makes it identifiable)
    n_lin = refit_linear_order(nom)
    nonzero = np.flatnonzero(nom.b)
    first_db = int(nonzero[0]) if not nom.is_ct and nonzero.size else 0
    refit_linear = [f"den{j + 1}" for j in range(n_lin)] + list(
        numerator_slots(N_MAX)[first_db : n_lin + 1]
    )
    P = n_params or n_free_parameters(plant, fitted=ctx.refit_linear)
    # the re-fitted parameters that carry the sign of G F (`FLIP_SIGN`)
    sign_slots = {
        NL_PIECEWISE: ("k1", "k2", "l1", "l2"),
        NL_TABULATED: ("out_scale",),
        NL_BACKLASH: ("out_scale",),
    }.get(nom.nl_kind, ("gain",))
    taus_tried = (
        delay_shortlist(
            est["y"],
            w_est,
            step=step_est,
            u0=float(u_est[0]),
            max_delay=delay_range(t_dom, n_est),
            t_dom=t_dom,
        )
        if screens
        else (0,)
    )

    # a piecewise-linear map held at the identity (`IDENTITY_MAP`: the profile
    # scores the identity map beside a piecewise-linear nominal only)
    identity = neutral.copy()
    for n, x in zip(PL_PARAMETERS, IDENTITY_PL, strict=True):
        identity[names.index(n)] = x

    def _row(name, base, start, flip, tau, held=neutral):
        free_names = base + [n for n in start if n not in base]
        if len(free_names) > P:
            raise ValueError(
                f"a {name} row frees {len(free_names)} parameters, "
                f"more than the padding's {P} (n_free_parameters)"
            )
        idx = np.full(P, S)
        idx[: len(free_names)] = [names.index(n) for n in free_names]
        theta0 = np.zeros(P)
        for j, n in enumerate(free_names):
            if n in start or n in flip:
                raw = raw_from_physical(n, {**flip, **start}[n])
                theta0[j] = (raw - anchor[names.index(n)]) / scale[names.index(n)]
        free = np.isin(np.array(names), free_names)
        row = Row(
            idx=np.asarray(idx),
            theta0=np.asarray(theta0),
            tau=np.asarray(tau),
            free=np.asarray(free),
            held=np.asarray(held),
        )
        return name, row

    rows = []
    twins = []
    for effect in DETERMINISTIC:
        taus = taus_tried if effect.name == "time_delay" else (0,)
        starts = effect.starts(ctx)
        for start in starts:
            if REFIT_LINEAR in start:
                twin = {n: EFFECT_NEUTRAL[n] for n in start if n in effect.level}
                if IDENTITY_MAP in start:  # the twin holds the same map
                    twin[IDENTITY_MAP] = 1.0
                if twin not in twins:
                    twins.append(twin)
        for start in starts:
            flip = (
                {n: -nominal_values[n] for n in sign_slots}
                if FLIP_SIGN in start
                else {}
            )
            # a start's gain (the stick-slip profile's) only where the gain is
            # re-fitted (identity maps; elsewhere the map's slopes carry it)
            base = refit_linear if REFIT_LINEAR in start else refit
            held = identity if IDENTITY_MAP in start else neutral
            start = {
                n: x
                for n, x in start.items()
                if n not in (FLIP_SIGN, REFIT_LINEAR, IDENTITY_MAP)
                and (n != "gain" or "gain" in base)
            }
            for tau in taus:
                rows.append(_row(effect.name, base, start, flip, tau, held))
    for twin in twins:
        held = identity if IDENTITY_MAP in twin else neutral
        if IDENTITY_MAP in twin:  # from its own linear fit (`identity_twin_start`)
            dens = [
                np.r_[1.0, [s.get(f"den{j}", 0.0) for j in range(1, n_lin + 1)]]
                for _, _, s, _ in ctx.stick_slip
                if IDENTITY_MAP in s
            ]
            start = identity_twin_start(
                nom, plant.linear, dt, np.asarray(v), np.asarray(est["y"]), dens
            )
            keep = set(refit_linear) | set(twin)  # its linear block and level
            twin = {**twin, **{n: x for n, x in start.items() if n in keep}}
        twin = {n: x for n, x in twin.items() if n != IDENTITY_MAP}
        rows.append(_row(LINEAR_TWIN, refit_linear, twin, {}, 0, held))
    tab_v, tab_u, tab_d = _pad_table(nom.tab_v, nom.tab_u, nom.tab_d)
    v_est, m_est = _pad_record(est["v"], L)
    y_est, _ = _pad_record(est["y"], L)
    v_val, m_val = _pad_record(val["v"], L)
    y_val, _ = _pad_record(val["y"], L)
    y_scale = max(float(np.std(est["y"])), 1e-12)
    noise_std = noise_std_differences(np.asarray(est["y"]) - w_est)
    # NumPy on the host: the fits stack and gather these without eager JAX ops
    f = lambda x: np.asarray(x, dtype=float)
    arrays = CaseArrays(
        v_est=f(v_est),
        y_est=f(y_est),
        m_est=f(m_est),
        v_val=f(v_val),
        y_val=f(y_val),
        m_val=f(m_val),
        dt=f(dt),
        is_ct=f(1.0 if nom.is_ct else 0.0),
        nl_kind=np.asarray(nom.nl_kind),
        tab_v=f(tab_v),
        tab_u=f(tab_u),
        tab_d=f(tab_d),
        b_disc=f(b_disc),
        ct_num=f(ct_num),
        ct_pad=f(ct_pad),
        den_lead=f(den_lead),
        anchor=f(anchor),
        scale=f(scale),
        neutral=f(neutral),
        out_centre=f(w_centre),
        out_half=f(w_half),
        y_scale=f(y_scale),
        u_scale=f(ctx.u_std),
        dw_half=f(ctx.dw_half),
        prior_weight=f(prior_weight(nominal_uncertainty, noise_std / y_scale)),
        noise_fir=f([1.0, 0.0, 0.0]),
        noise_ar=f(0.0),
        noise_dfir=f([0.0, 0.0, 0.0]),
        noise_dar=f(0.0),
    )
    return Prepared(
        arrays,
        rows,
        ctx,
        nom,
        n_est,
        n_val,
        w_est,
        w_val,
        u_val,
        bool(fitted_nominal),
        closed,
    )


def finite_sse(fits: dict) -> np.ndarray:
    """Each row's estimation SSE, a failed (non-finite) fit counting as infinite."""
    return np.where(np.isfinite(fits["sse_est"]), fits["sse_est"], np.inf)


def validation_sse(prep: Prepared, fits: dict) -> np.ndarray:
    """Each row's validation SSE (non-finite: infinite)."""
    n = prep.n_val
    r = np.asarray(fits["y_val"])[:, :n] - np.asarray(prep.arrays.y_val)[None, :n]
    sse = np.sum(r**2, axis=1)
    return np.where(np.isfinite(sse), sse, np.inf)


def n_fitted(prep: Prepared, row: int) -> int:
    """Parameters row `row` fits: its free slots among the re-fit's and the
    effect's (`prep.arrays.anchor`), not the padding."""
    return int(np.sum(np.asarray(prep.rows[row][1].idx) < prep.arrays.anchor.shape[0]))


def n_beyond(prep: Prepared, row: int, ref: int) -> int:
    """Slots row `row` frees that row `ref` does not: the parameters by which the
    model freeing both (their union, which nests each) exceeds `ref`'s."""
    free = np.asarray(prep.rows[row][1].free)
    return int(np.sum(free & ~np.asarray(prep.rows[ref][1].free)))


def best_row_per_class(
    prep: Prepared, sse: np.ndarray, val_sse: np.ndarray
) -> dict[str, int]:
    """`{class name: its row with the lowest estimation SSE}` (first one on ties);
    the finishing stage and the attribution must agree on it.

    A row that frees an `alternative` slot of its effect (the play on the output
    of G) stands for the class only if it beats the class's best row of the
    contract's form on both the estimation and the validation SSE.

    A row that frees an `extension` slot of its effect (the slip jump of a
    backlash) stands for the class only if it beats the class's best row without
    one by the nested likelihood ratio $(S_0 - S_1) / (S_1 / (n - p_1)) >
    2 \\ln(1 / \\alpha)$ ($\\chi^2_1$ under white noise; the bound of
    `attribute._nested_lr` for one comparison), confirmed by a lower validation
    SSE (`val_sse`; the ratio trusts white noise): the extra slot must earn its
    place, as the effect must over the re-fit.

    A `REFIT_LINEAR` row (beside hamjax's own nominal) re-fits the whole linear
    block as well, so what it gains over the nominal may be the linear block's
    alone (a closed loop's dynamics, an order the selection missed). It stands
    for its class only if it first beats its `LINEAR_TWIN` (the same linear
    re-fit with the effect held neutral) by the same nested ratio, the twin's
    row nesting it with the effect's own parameters the difference, confirmed
    on validation. The twin stands for no class. A row that holds the map at
    the identity (`IDENTITY_MAP`) has a twin that holds it there too: against
    the twin with the nominal's map the two would not be nested, and an
    integrating loop without stiction whose fitted nominal's map was wrong
    named the play for what the identity map alone explained (three loops of
    seeds 1-4 of the control-loop benchmark, measured)."""
    names = slot_names(N_MAX)
    extension = {e.name: [names.index(s) for s in e.extension] for e in DETERMINISTIC}
    alternative = {
        e.name: [names.index(s) for s in e.alternative] for e in DETERMINISTIC
    }
    best: dict[str, int] = {}
    best_ext: dict[str, int] = {}
    best_alt: dict[str, int] = {}
    threshold = 2.0 * np.log(1.0 / LR_ALPHA)
    twin = [k for k, (name, _) in enumerate(prep.rows) if name == LINEAR_TWIN]

    def beats(k: int, k0: int) -> bool:
        p = n_fitted(prep, k)
        s2 = sse[k] / max(prep.n_est - p, 1)
        gain = sse[k0] - sse[k]
        lr = gain / s2 if s2 > 0 else np.inf * np.sign(gain)
        return bool(lr > threshold and val_sse[k] < val_sse[k0])

    for k, (name, row) in enumerate(prep.rows):
        if name == LINEAR_TWIN:
            continue
        if refits_linear(row):
            # its twin: the linear re-fit whose free slots it frees too, with
            # the slots neither frees held at the same values (the map)
            k0 = [
                j
                for j in twin
                if np.all(row.free >= prep.rows[j][1].free)
                and np.array_equal(row.held, prep.rows[j][1].held)
            ]
            if not (k0 and beats(k, k0[0])):
                continue
        if any(row.free[i] for i in alternative.get(name, [])):
            table = best_alt
        elif any(row.free[i] for i in extension.get(name, [])):
            table = best_ext
        else:
            table = best
        if name not in table or sse[k] < sse[table[name]]:
            table[name] = k
    for name, k in best_ext.items():
        if name not in best:
            best[name] = k
            continue
        if beats(k, best[name]):
            best[name] = k
    for name, k in best_alt.items():
        k0 = best.get(name)
        if k0 is None or (sse[k] < sse[k0] and val_sse[k] < val_sse[k0]):
            best[name] = k
    return best


def refits_linear(row: Row) -> bool:
    """Whether `row` re-fits the numerator too (a `REFIT_LINEAR` start)."""
    names = slot_names(N_MAX)
    return any(row.free[names.index(n)] for n in numerator_slots(N_MAX))


def frees_valve_start(row: Row) -> bool:
    """Whether the row fits the valve's start (`valve_start`: the stick-slip
    profile's starts)."""
    return bool(np.asarray(row.free)[slot_index("valve_start", N_MAX)])


def starts_at_nominal_numerator(row: Row) -> bool:
    """Whether a `refits_linear` row starts at the nominal's numerator (every
    change `db..` at 0), far from its own optimum, rather than at a fitted one
    (the stick-slip profile's starts, `stick_slip_profile`)."""
    names = slot_names(N_MAX)
    numerator = {names.index(n) for n in numerator_slots(N_MAX)}
    idx, theta0 = np.asarray(row.idx), np.asarray(row.theta0)
    return not any(theta0[j] != 0 for j, i in enumerate(idx) if int(i) in numerator)


def n_free_parameters(plant: Hammerstein, *, fitted: bool = False) -> int:
    """Width of the compact parameter vector this plant's rows need; `fitted`:
    the plant is hamjax's own discrete fit, whose `REFIT_LINEAR` row frees the
    denominator, the numerator and `MAX_EFFECT_SLOTS` effect slots."""
    nom = describe_nominal(plant)
    n_den = nom.order if nom.is_ct else nom.den.shape[0] - 1
    nl = {NL_PIECEWISE: 6, NL_TABULATED: 2, NL_BACKLASH: 2}.get(nom.nl_kind, 1)
    width = n_den + nl + MAX_EFFECT_SLOTS
    if fitted and not nom.is_ct:
        width = max(width, 2 * refit_linear_order(nom) + 1 + MAX_EFFECT_SLOTS)
    return width


def _response_numpy(linear, u: np.ndarray, dt: float) -> np.ndarray:
    """Nominal linear response from rest (NumPy: no compilation per record
    length), along the last axis of `u`: a continuous block through its exact
    zero-order-hold state space (`zoh_tf`, `state_space_numpy`)."""
    u = np.asarray(u, float)
    if isinstance(linear, ContinuousTransferFunction):
        A, B, C, D = zoh_tf(np.asarray(linear.num), np.asarray(linear.den), dt, xp=np)
        return state_space_numpy(A, B, C, D, u)
    b, a = np.asarray(linear.b), np.asarray(linear.a)
    n = max(a.shape[0], b.shape[0])
    b = np.r_[b, np.zeros(n - b.shape[0])]
    a = np.r_[a, np.zeros(n - a.shape[0])]
    return lfilter_numpy(b, a, u)  # a[0] == 1


def _static_numpy(nom: Nominal, v: np.ndarray) -> np.ndarray:
    if nom.nl_kind == NL_PIECEWISE:
        return piecewise_linear_map(v, *nom.pl, xp=np)
    if nom.nl_kind == NL_TABULATED:
        return np.interp(v, nom.tab_v, nom.tab_u)
    if nom.nl_kind == NL_BACKLASH:
        return _backlash_numpy(nom, np.asarray(v, float))
    return np.asarray(v, float)


def _backlash_numpy(nom: Nominal, v: np.ndarray) -> np.ndarray:
    """`Backlash.step` over `v` from its default start (centred in the play at
    `v[0]`), on Python floats (no compilation per record length)."""
    grid, fa_all, fd_all = nom.tab_v, nom.tab_u, nom.tab_d
    fa, fd = np.interp(v, grid, fa_all).tolist(), np.interp(v, grid, fd_all).tolist()
    v = v.tolist()
    u = (fa[0] + fd[0]) / 2
    on_a, on_d, v_prev = u == fa[0], u == fd[0], v[0]
    out = np.empty(len(v))
    for k, vk in enumerate(v):
        rising, falling = vk > v_prev, vk < v_prev
        take_a = rising and (on_a or fa[k] >= u)
        take_d = falling and (on_d or fd[k] <= u)
        u = fa[k] if take_a else fd[k] if take_d else u
        if rising or falling:
            on_a, on_d = take_a or u == fa[k], take_d or u == fd[k]
        v_prev, out[k] = vk, u
    return out


def nominal_output(plant: Hammerstein, v: np.ndarray, dt: float) -> np.ndarray:
    """The nominal plant's output from rest for the input samples `v` (NumPy)."""
    plant = fold_output_scale(plant)
    return _response_numpy(plant.linear, _static_numpy(describe_nominal(plant), v), dt)
