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
    return np.concatenate([np.zeros(m), x[: x.shape[0] - m]])


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
    pass for a shift."""
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
    best: dict[int, float] = {}
    for m in range(max_delay + 1):
        # each whole part's delayed outputs once, for all its fractions
        cols = [delayed_response(x, s, float(u0), m) for x, s in series]
        later = [_shift(c, 1) for c in cols]
        for f in np.arange(0.0, 1.0, SCREEN_STEP):
            if not 0 < m + f <= max_delay:
                continue
            X = np.stack(
                [(1 - f) * c + f * c1 for c, c1 in zip(cols, later, strict=True)], 1
            )
            coef = np.linalg.lstsq(X, y, rcond=None)[0]
            sse = float(np.sum((y - X @ coef) ** 2))
            best[m] = min(best.get(m, np.inf), sse)
    return tuple(sorted(best, key=lambda m: best[m])[:keep])


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
