r"""`time_delay`: $v'(t) = v(t - \tau)$, $\tau = m + f$ samples: a whole part $m$
(one row each) and a fraction $0 \le f < 1$ fitted continuously (`delay_frac`)."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..._filters import lfilter_numpy
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
    # written out, not `jnp.convolve`: under `vmap` XLA's convolution rounds a
    # row's taps differently with the batch size (seen at 28 vs 56 rows)
    zero = jnp.zeros(1, b.dtype)
    b = jnp.concatenate([b, zero]) * (1 - f) + jnp.concatenate([zero, b]) * f
    a = jnp.concatenate([a, zero])
    return b, a


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
    """$w$ through the unit-gain lag $(1 - c) / (1 - c q^{-1})$, $c = e^{-1/t}$,
    started at rest at $w_0$ (`lfilter_numpy` of $w - w_0$, plus $w_0$)."""
    c = float(np.exp(-1.0 / t))
    return w[0] + lfilter_numpy([1.0 - c, 0.0], [1.0, -c], w - w[0])


def delay_shortlist(
    y: np.ndarray, w: np.ndarray, *, max_delay: int, t_dom: float, keep: int = 2
) -> tuple[int, ...]:
    """The whole parts $m$ of the `keep` delays $m + f$ ($f$ on a grid of
    `SCREEN_STEP`, $0 < m + f \\le$ `max_delay`) whose shifted nominal output
    fits `y` best, one per whole part (a cheap screen; the rows of the kept $m$
    then fit $f$ with the nominal re-fit).

    The shift is split as in `fractional_split`, and the fit is linear least
    squares on the shifted $w$ and the same through the lag of the nominal's
    dominant time constant $T$ (`t_dom`, samples; skipped when not finite or
    under one sample): for a first-order mode $\\partial w / \\partial T \\propto
    w - \\mathrm{lag}_T(w)$, so the two span the nominal's re-fit of its gain and
    $T$ to first order, and a mis-set time constant (15-20 % is common) does not
    pass for a shift."""
    y, w = np.asarray(y, float), np.asarray(w, float)
    n = w.shape[0]
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(y))):
        # an overflowing nominal: nothing to screen; the fits report it as not
        # finite (`DiagnosisNotFinite`), a least-squares solve here would raise
        return tuple(range(1, min(keep, max_delay) + 1))
    series = [w] + ([_lag(w, t_dom)] if np.isfinite(t_dom) and t_dom >= 1 else [])
    # each series with its first value held before t = 0
    held = [np.concatenate([np.full(max_delay + 1, x[0]), x]) for x in series]
    best: dict[int, float] = {}
    for d in np.arange(SCREEN_STEP, max_delay + 1e-9, SCREEN_STEP):
        m = int(np.floor(d + 1e-9))
        f = float(d - m)
        lo, hi = max_delay + 1 - m, max_delay - m
        X = np.stack([(1 - f) * h[lo : lo + n] + f * h[hi : hi + n] for h in held], 1)
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
