r"""`time_delay`: $v'(t) = v(t - \tau)$, $\tau = m + f$ samples: a whole part $m$
(one row each) and a fraction $0 \le f < 1$ fitted continuously (`delay_frac`)."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..._filters import lfilter_numpy
from ..._linalg import polymul
from ._base import AbstractEffect, StartContext


# The least whole-sample range screened (`delay_range` widens it to the nominal's
# settling time); the neutral delay is 0.
MAX_DELAY = 8
SCREEN_STEP = 0.25  # resolution (samples) of the shortlist's fractional screen
FRACTIONS = np.arange(0.0, 1.0, SCREEN_STEP)
# the part of |y|^2 within which the screen's best whole parts are solved again
SCREEN_TOL = 1e-6
SCREEN_ELEMENTS = 1 << 20  # shifted samples the screen holds at once (8 MiB)


def delay(v: Float[Array, " time"], tau: Int[Array, ""]) -> Float[Array, " time"]:
    """$v_{k-\\tau}$, holding $v_0$ before $t = 0$ (the contract); $\\tau = 0$ is neutral."""
    idx = jnp.maximum(jnp.arange(v.shape[0]) - tau, 0)
    return jnp.asarray(v)[idx]


def fractional_split(
    b: Float[Array, " n"], a: Float[Array, " n"], f: Float[Array, ""]
) -> tuple[Float[Array, " n1"], Float[Array, " n1"]]:
    r"""The filter `(b, a)` behind the fraction $f$ of a sample of delay: its input
    $u'_k = (1 - f) u_k + f u_{k-1}$, i.e. $b \cdot ((1 - f) + f q^{-1})$ (`a` padded).

    For a zero-order-hold input $u$ a delay of $f h$ shifts the hold's edges by
    $f h$, so over each output interval the plant sees $u_{k-1}$ for $f h$ and
    $u_k$ for $(1 - f) h$: the modified z-transform (Jury). Behind an integrator
    the split weights are exactly $(1 - f, f)$; behind a lag of time constant $T$
    they are $(1 - e^{-(1-f)h/T}) / (1 - e^{-h/T})$ and its complement, equal to
    $(1 - f, f)$ to first order in $h / T$. $f = 0$ is neutral bit for bit (a
    trailing zero tap and state)."""
    return polymul(b, jnp.stack([1 - f, f])), jnp.concatenate(
        [a, jnp.zeros(1, a.dtype)]
    )


def dominant_time_constant(den: np.ndarray, is_ct: bool, dt: float) -> float:
    """The slowest stable time constant of the nominal linear block, in samples
    (`den`: continuous, highest power first, or discrete `a`); `inf` for a pole
    on or beyond the stability boundary, 0 for a block with no pole."""
    roots = np.roots(np.asarray(den, float))
    if roots.size == 0:
        return 0.0
    # decay per sample: -Re(s) dt of a continuous pole s, -ln|z| of a discrete z
    if is_ct:
        rate = -roots.real * dt
    else:
        rate = -np.log(np.maximum(np.abs(roots), 1e-300))
    rate = rate[np.isfinite(rate)]
    if np.any(rate <= 0):
        return float("inf")
    return float(1.0 / rate.min()) if rate.size else 0.0


SETTLING = 4.0  # time constants to settle within 2 % (e^{-4} = 0.018)


def delay_range(t_dom: float, n: int) -> int:
    r"""The largest whole-sample delay screened: the nominal's settling time
    `SETTLING` $T$ ($T$ its dominant time constant in samples,
    `dominant_time_constant`), at least `MAX_DELAY`, at most a tenth of the record.

    A delay up to about $T$ is what a lag can mimic (the pair that short or slow
    records cannot tell apart, so both must be on the table); beyond the settling
    time a delay shows as dead time after which the nominal response is already
    complete, and a tenth of the record keeps nine tenths of it to fit on.
    """
    t = MAX_DELAY if not np.isfinite(t_dom) else max(MAX_DELAY, SETTLING * t_dom)
    return int(max(1, min(np.ceil(t), n // 10)))


def _lag(w: np.ndarray, t: float) -> np.ndarray:
    """`w` through the unit-gain lag $(1 - c) / (1 - c q^{-1})$, $c = e^{-1/t}$,
    from rest (`lfilter_numpy`)."""
    c = float(np.exp(-1.0 / t))
    return lfilter_numpy([1.0 - c, 0.0], [1.0, -c], w)


def _shift(x: np.ndarray, m: int) -> np.ndarray:
    """$x_{k-m}$, zero before $t = 0$ (a block at rest)."""
    if m == 0:
        return x
    n = x.shape[0]
    return np.concatenate([np.zeros(min(m, n)), x[: max(n - m, 0)]])


def delayed_response(w: np.ndarray, step: np.ndarray, u0: float, m: int) -> np.ndarray:
    r"""The output of a linear block from rest for its input delayed by $m$
    samples with $u_0$ held before $t = 0$ (`delay`, the contract), from its
    response `w` to the undelayed input and `step` to the unit step.

    The held input is $u_{k-m}$ for $k \ge m$ and $u_0$ before: $u$ shifted from
    rest plus a pulse of height $u_0$ over $k < m$, so the output is
    $w_{k-m} + u_0 (s_k - s_{k-m})$ ($w$, $s$ zero before $t = 0$). A static map,
    or a backlash started in its play, commutes with the delay (a held $v_0$
    gives a held $u_0$), so `w` may be a whole nominal's output."""
    return _shift(w, m) + u0 * (step - _shift(step, m))


def _lstsq_sse(series, y: np.ndarray, u0: float, m: int, max_delay: int) -> float:
    """The least residual sum of squares of `y` on the delayed outputs of
    `series` (pairs of a response and its step response) over the delays
    $m + f$ in range (`_in_range`; `delayed_response`, the fraction split as in
    `fractional_split`): `numpy.linalg.lstsq` on the columns scaled to unit
    norm (`_norm`; its rank cut-off is relative to the largest singular value:
    behind a nominal with a time constant of $10^{15}$ samples, an integrator
    in all but name, the lag's column is $10^{-15}$ of the other and was
    dropped, though it is as well determined)."""
    cols = [delayed_response(x, s, u0, m) for x, s in series]
    best = np.inf
    for f in FRACTIONS[_in_range(max_delay)[m]]:
        X = [(1 - f) * c + f * _shift(c, 1) for c in cols]
        X = np.stack([x / (_norm(x) or 1.0) for x in X], 1)  # a cut-off blind to scale
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        best = min(best, float(np.sum((y - X @ coef) ** 2)))
    return best


def _norm(x: np.ndarray) -> float:
    """The Euclidean norm of `x`, free of overflow (`scipy.linalg.norm`: BLAS
    `nrm2` scales as it sums)."""
    from scipy import linalg

    return float(linalg.norm(x))


def _in_range(max_delay: int) -> np.ndarray:
    """Which delays $m + f$ the screen tries: rows $m = 0, \\dots,$ `max_delay`,
    columns `FRACTIONS`, $0 < m + f \\le$ `max_delay`."""
    total = np.arange(max_delay + 1)[:, None] + FRACTIONS[None, :]
    return (total > 0) & (total <= max_delay)


def _shifted_products(x: np.ndarray, top: int, Z: np.ndarray) -> np.ndarray:
    r"""Row $m = 0, \dots,$ `top`: $x_{k - m}$ (zero before $t = 0$, `_shift`)
    times the columns of `Z`, at most `SCREEN_ELEMENTS` shifted samples at once."""
    n = x.shape[0]
    window = np.lib.stride_tricks.sliding_window_view(np.r_[np.zeros(top), x], n)
    rows = max(1, SCREEN_ELEMENTS // max(n, 1))
    return np.concatenate(
        [
            window[top - np.arange(lo, min(lo + rows, top + 1))] @ Z
            for lo in range(0, top + 1, rows)
        ]
    )


def _unit(x: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pair `(x, s)` over the norm of `x` (`_norm`), or as it is where `x` is
    zero."""
    size = _norm(x)
    return (x / size, s / size) if size > 0 else (x, s)


def _screen_sse(
    series, y: np.ndarray, u0: float, max_delay: int
) -> tuple[np.ndarray, np.ndarray]:
    r"""`_lstsq_sse` of every whole part $m \le$ `max_delay` (rows) and fraction
    (columns; `inf` where $m + f$ is out of range) from the Gram matrices of the
    columns and `y` ($\lVert y \rVert^2 - b^\top G^{-1} b$), and per whole part
    whether that may be off by more than a quarter of `SCREEN_TOL`
    $\lVert y \rVert^2$.

    A series' column is $(1 - f) A_m + f A_{m+1} + u_0 t_f$ with $A_m = q^{-m} g$,
    $g = x - u_0 s$ (`delayed_response`) and $t_f = (1 - f) s + f q^{-1} s$, so
    its products are those of the rows $A_m$ with `y`, $s$ and $q^{-1} s$ (one
    matrix product) and of the rows among themselves: $A_m \cdot A'_{m+j}$ is a
    partial sum of $g \cdot q^{-j} g'$ over the first $n - m$ samples. A second
    series enters orthogonalised against the first and both at unit norm (the
    same span).

    Each product is a sum of at most $n$ terms, each term within
    $\epsilon$ of its size, so an entry of $G$ is within $n \epsilon c^2$ of
    its value ($c = \lVert g \rVert + |u_0| \lVert s \rVert$ bounds a column's
    norm), and $\lVert y \rVert^2 - b^\top G^{-1} b$ within about
    $n \epsilon \kappa \lVert y \rVert^2$ with $\kappa = 1 / (1 - \rho^2)$ for
    columns of correlation $\rho$, times $c^2 / G_{ii}$ for a column that
    cancels to less than its bound. A whole part where that exceeds a quarter
    of `SCREEN_TOL` (or whose residual is not finite or below that much under
    zero) is flagged for the caller to solve."""
    n = y.shape[0]
    pairs = [_unit(np.asarray(x, float), np.asarray(s, float)) for x, s in series]
    if len(pairs) == 2 and np.any(pairs[0][0]):
        (x1, s1), (x2, s2) = pairs
        alpha = x1 @ x2  # x1 at unit norm
        pairs[1] = _unit(x2 - alpha * x1, s2 - alpha * s1)
    g = [x - u0 * s for x, s in pairs]
    bound = [
        np.sqrt(gi @ gi) + abs(u0) * np.sqrt(s @ s)
        for gi, (_, s) in zip(g, pairs, strict=True)
    ]
    k = len(pairs)
    t = [s for _, s in pairs] + [_shift(s, 1) for _, s in pairs]
    Z = np.stack([y, *t], 1)
    P = [_shifted_products(gi, max_delay + 1, Z) for gi in g]
    ms = np.arange(max_delay + 1)
    c0, c1 = 1.0 - FRACTIONS[None, :], FRACTIONS[None, :]  # weights of m, m + 1

    def tail(p):  # sums over the first n - m samples, m = 0..max_delay + 1
        return np.cumsum(p)[n - 1 - np.arange(max_delay + 2)][:, None]

    def with_t(i, j):  # A_i . t_j, rows m, both fraction-split
        lo, hi = P[i][:, 1 + j : 2 + j], P[i][:, 1 + k + j : 2 + k + j]
        return c0 * (c0 * lo[ms] + c1 * hi[ms]) + c1 * (
            c0 * lo[ms + 1] + c1 * hi[ms + 1]
        )

    Xy = [
        c0 * P[i][ms, :1]
        + c1 * P[i][ms + 1, :1]
        + u0 * (c0 * (t[i] @ y) + c1 * (t[k + i] @ y))
        for i in range(k)
    ]
    G = {}
    for i in range(k):
        for j in range(i, k):
            q00 = tail(g[i] * g[j])
            q01 = tail(g[i] * _shift(g[j], 1))
            q10 = tail(_shift(g[i], 1) * g[j])
            tt = (
                c0 * c0 * (t[i] @ t[j])
                + c0 * c1 * (t[i] @ t[k + j] + t[k + i] @ t[j])
                + c1 * c1 * (t[k + i] @ t[k + j])
            )
            G[i, j] = (
                c0 * c0 * q00[ms]
                + c0 * c1 * (q01[ms] + q10[ms])
                + c1 * c1 * q00[ms + 1]
                + u0 * (with_t(i, j) + with_t(j, i))
                + u0 * u0 * tt
            )
    # a column that cancels to nothing gives inf or nan here: flagged, not used
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        tiny = np.finfo(float).tiny
        g11 = np.maximum(G[0, 0], tiny)
        fit = Xy[0] ** 2 / g11
        kappa = bound[0] ** 2 / g11
        if k == 2:
            g22 = np.maximum(G[1, 1], tiny)
            rest = np.maximum(g22 - G[0, 1] ** 2 / g11, tiny)  # Schur complement
            fit = fit + (Xy[1] - G[0, 1] * Xy[0] / g11) ** 2 / rest
            kappa = np.maximum(kappa, bound[1] ** 2 / g22) * g22 / rest
        y_y = float(y @ y)
        sse = y_y - fit
        out = ~_in_range(max_delay)
        error = n * np.finfo(float).eps * kappa * y_y
        doubt = ~np.isfinite(sse) | (sse < -SCREEN_TOL / 4 * y_y)
        doubt |= ~(error <= SCREEN_TOL / 4 * y_y)
    sse[out] = np.inf
    return sse, np.any(doubt & ~out, axis=1)


def delay_shortlist(
    y: np.ndarray,
    w: np.ndarray,
    *,
    step: np.ndarray,
    u0: float,
    max_delay: int,
    t_dom: float,
    keep: int = 2,
) -> tuple[int, ...]:
    """The whole parts $m$ of the `keep` delays $m + f$ ($f$ on a grid of
    `SCREEN_STEP`, $0 < m + f \\le$ `max_delay`) whose delayed nominal output
    fits `y` best, one per whole part (a cheap screen; the rows of the kept $m$
    then fit $f$ with the nominal re-fit).

    `w`: the nominal output from rest, `step` its linear block's unit-step
    response, `u0` the block's first input: the delayed outputs are those of the
    model (`delayed_response`; shifting `w` itself would hold $w_0$ instead of
    $v_0$, and behind a slow lag the difference over the first $m$ samples
    outweighs the delay's own signature). The fraction is split as in
    `fractional_split` (from rest). The fit is linear least squares on the
    delayed output and the same through the lag of the nominal's dominant time
    constant $T$ (`t_dom`, samples; skipped when not finite or under one
    sample): for a first-order mode $\\partial w / \\partial T \\propto w -
    \\mathrm{lag}_T(w)$, so the two span the nominal's re-fit of its gain and
    $T$ to first order, and a mis-set time constant (15-20 % is common) does not
    pass for a shift. Every delay's residual comes from Gram products
    (`_screen_sse`, one pass over the record); the least squares itself
    (`_lstsq_sse`) ranks the whole parts within `SCREEN_TOL`
    $\\lVert y \\rVert^2$ of the `keep`-th best and any the products cannot
    judge to a quarter of that, so the shortlist is the solves' own (tested
    against a brute-force ranking)."""
    y, w = np.asarray(y, float), np.asarray(w, float)
    step = np.asarray(step, float)
    if not (
        np.all(np.isfinite(w)) and np.all(np.isfinite(y)) and np.all(np.isfinite(step))
    ):
        # an overflowing nominal: nothing to screen; the fits report it as not
        # finite (`DiagnosisNotFinite`), a least-squares solve here would raise
        return tuple(range(1, min(keep, max_delay) + 1))
    series = [(w, step)]
    if np.isfinite(t_dom) and t_dom >= 1:
        # the lag is linear and time-invariant: it commutes with the delay
        series.append((_lag(w, t_dom), _lag(step, t_dom)))
    # every delay's residual from the Gram matrices (`_screen_sse`), then the
    # least-squares solve itself for the whole parts it may have misjudged and
    # for those within `SCREEN_TOL` |y|^2 of the `keep`-th best: the ranking is
    # the solves' own (a part the products misjudge by under a quarter of that
    # cannot fall outside it when the solves would keep it)
    if max_delay + 2 <= y.shape[0]:
        sse, unsure = _screen_sse(series, y, float(u0), max_delay)
        approx = sse.min(axis=1)
    else:  # a delay as long as the record: solve every one
        approx, unsure = np.zeros(max_delay + 1), np.ones(max_delay + 1, bool)
    valid = _in_range(max_delay).any(axis=1)
    if keep < 1 or not valid.any():
        return ()
    unsure &= valid

    def solve(m):
        return _lstsq_sse(series, y, float(u0), int(m), max_delay)

    best = {int(m): solve(m) for m in np.flatnonzero(unsure)}
    approx[unsure] = [best[int(m)] for m in np.flatnonzero(unsure)]
    approx[~valid] = np.inf
    cutoff = np.sort(approx)[min(keep, int(valid.sum())) - 1]
    close = valid & ~unsure & (approx <= cutoff + SCREEN_TOL * float(y @ y))
    best |= {int(m): solve(m) for m in np.flatnonzero(close)}
    return tuple(sorted(best, key=lambda m: (best[m], m))[:keep])


class TimeDelayEffect(AbstractEffect):
    """Delay $m + f$: $m$ from `delay_shortlist` (one row each), $f$ fitted
    (`fractional_split`); the slowly varying or fractional transport delay of a
    physical plant is named through its best constant $m + f$."""

    name = "time_delay"
    slots = ("delay_frac",)
    neutral = {"delay_frac": 0.0}
    unit_interval = ("delay_frac",)

    def scales(self, ctx: StartContext) -> dict[str, float]:
        return {"delay_frac": 1.0}

    def starts(self, ctx: StartContext) -> list[dict[str, float]]:
        return [{"delay_frac": 0.5}]
