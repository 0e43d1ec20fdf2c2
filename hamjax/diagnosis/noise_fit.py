"""Fit the two noise-model effects (`drift`, `coloured_noise`) on the estimation
residual and score them by one-step-ahead prediction on the validation residual.

`fit_noise_family` fits the whole family of noise models of the one-likelihood
rule (`decide`): white, AR(1), AR(2), ARMA(1,1), a local level (a random-walk
level seen through its steady-state Kalman predictor) and the flicker model
ARFIMA(0, d, 0) (`effects/coloured_noise.py`), each by prediction error
on one candidate's estimation residual, and returns the one-step-ahead
innovations on both records.
"""

import functools as ft
import threading
from collections.abc import Iterable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._filters import lfilter_numpy
from .._linalg import fixed_order_sum
from .effects.coloured_noise import (
    ar1_errors,
    fit_ar1,
    fit_fractional,
    fractional_errors,
    fractional_errors_numpy,
)
from .effects.drift import (
    fit_local_level,
    fit_split_local_level,
    local_level_errors,
)
from .layout import bucket


class NoiseFit(eqx.Module):
    """Fitted noise models and their validation one-step-ahead errors.

    `drift` is the local level with gain at most `effects.drift.MAX_DRIFT_GAIN`
    (a white part at least half the innovations, `effects/drift.py`);
    `coloured_noise` is the AR(1) predictor, the local level of higher gain or the
    fractional (flicker) predictor, whichever has the lowest estimation SSE
    (`effects/coloured_noise.py`). `coloured_param`, `coloured_is_level` and
    `coloured_sse` are the better of the two low-order ones (its pole or gain);
    `fractional_d` and `fractional_sse` the flicker model's, `is_fractional`
    whether it is the class's; `coloured_errors` the class's validation errors."""

    coloured_param: Float[Array, ""]
    coloured_is_level: Bool[Array, ""]
    coloured_errors: Float[Array, " L"]
    coloured_sse: Float[Array, ""]  # on the estimation record
    level_alpha: Float[Array, ""]
    level_errors: Float[Array, " L"]
    level_sse: Float[Array, ""]
    fractional_d: Float[Array, ""]
    fractional_sse: Float[Array, ""]
    is_fractional: Bool[Array, ""]


@eqx.filter_jit
def fit_noise_models(
    r_est: Float[Array, " L"],
    m_est: Float[Array, " L"],
    r_val: Float[Array, " L"],
) -> NoiseFit:
    """The drift and coloured-noise predictors fitted on `r_est`, applied to
    `r_val`."""
    a = fit_ar1(r_est, m_est)
    s_ar1 = fixed_order_sum(m_est * ar1_errors(r_est, a) ** 2)
    alpha, s_drift, high, s_high = fit_split_local_level(r_est, m_est)
    d, s_frac = fit_fractional(r_est, m_est)
    is_level = s_high < s_ar1
    s_low = jnp.minimum(s_high, s_ar1)
    is_frac = s_frac < s_low
    e_low = jnp.where(is_level, local_level_errors(r_val, high), ar1_errors(r_val, a))
    return NoiseFit(
        jnp.where(is_level, high, a),
        is_level,
        jnp.where(is_frac, fractional_errors(r_val, d), e_low),
        s_low,
        alpha,
        local_level_errors(r_val, alpha),
        s_drift,
        d,
        s_frac,
        is_frac,
    )


class NoisePredictor(NamedTuple):
    """One fitted noise-model effect, as `noise_fit_numpy` returns it."""

    value: float  # its parameter
    errors: np.ndarray  # validation one-step-ahead errors
    name: str  # the parameter's name: "ar1_pole", "level_gain" or "fractional_d"
    est_sse: float  # one-step SSE on the estimation record
    # `(name, value)` of the predictor whose filter `noise_filter` gives (itself,
    # or for the fractional one, which has no finite filter, the low-order
    # predictor of least estimation SSE: `whitening_stand_in`)
    whitening: tuple[str, float]


def noise_fit_numpy(r_est: np.ndarray, r_val: np.ndarray) -> dict:
    """Convenience wrapper on unpadded NumPy residuals (padded to the diagnosis's
    record buckets, so records of many lengths share a few compilations):
    `{effect: NoisePredictor}`."""
    n = bucket(max(r_est.shape[0], r_val.shape[0]))
    pe = np.zeros(n)
    pe[: r_est.shape[0]] = r_est
    me = np.zeros(n)
    me[: r_est.shape[0]] = 1.0
    pv = np.zeros(n)
    pv[: r_val.shape[0]] = r_val
    f = fit_noise_models(jnp.asarray(pe), jnp.asarray(me), jnp.asarray(pv))
    k = r_val.shape[0]
    low = (
        "level_gain" if bool(f.coloured_is_level) else "ar1_pole",
        float(f.coloured_param),
    )
    drift = ("level_gain", float(f.level_alpha))
    if bool(f.is_fractional):
        stand_in = whitening_stand_in(
            (low, float(f.coloured_sse)), (drift, float(f.level_sse))
        )
        coloured = ("fractional_d", float(f.fractional_d), float(f.fractional_sse))
    else:
        stand_in, coloured = low, (*low, float(f.coloured_sse))
    return {
        "coloured_noise": NoisePredictor(
            coloured[1],
            np.asarray(f.coloured_errors)[:k],
            coloured[0],
            coloured[2],
            stand_in,
        ),
        "drift": NoisePredictor(
            drift[1],
            np.asarray(f.level_errors)[:k],
            "level_gain",
            float(f.level_sse),
            drift,
        ),
    }


def whitening_stand_in(*fits: tuple[tuple[str, float], float]) -> tuple[str, float]:
    """The fractional predictor's stand-in for `noise_filter`: of the low-order
    predictors `((name, value), estimation SSE)`, the one of least SSE (the
    prediction-error re-fits need a finite filter; the judgement through the
    noise model uses the fractional one itself, `predictor_errors`)."""
    return min(fits, key=lambda f: f[1])[0]


def noise_filter(name: str, value: float) -> tuple[np.ndarray, float]:
    """The one-step-ahead error filter $A(q) = (f_0 + f_1 q^{-1} + f_2 q^{-2}) /
    (1 + g q^{-1})$ of the fitted noise predictor `name` (`"ar1_pole"` or
    `"level_gain"`, as `noise_fit_numpy` reports it) with parameter `value`:
    $1 - a q^{-1}$ for the AR(1), $\\frac{1 - q^{-1}}{1 - (1 - \\alpha) q^{-1}}$
    for the local level. Returns `(f, g)`, the form of
    `augmented.CaseArrays.noise_fir` and `noise_ar`."""
    if name == "ar1_pole":
        return np.array([1.0, -value, 0.0]), 0.0
    if name == "level_gain":
        return np.array([1.0, -1.0, 0.0]), value - 1.0
    if name == "fractional_d":
        raise ValueError(
            "noise_filter: the fractional predictor has no finite filter "
            "(its NoisePredictor.whitening stands in)"
        )
    raise ValueError(f"noise_filter: unknown noise predictor {name!r}")


def noise_direction(name: str) -> tuple[np.ndarray, float]:
    """How `noise_filter(name, value)` moves with `value`: `(df, dg)`, the
    derivative of its `(f, g)` (the filter is affine in the parameter), the form of
    `augmented.CaseArrays.noise_dfir` and `noise_dar` for a prediction-error fit
    that fits the predictor's parameter jointly (`fit.normal_equations`)."""
    if name == "ar1_pole":
        return np.array([0.0, -1.0, 0.0]), 0.0
    if name == "level_gain":
        return np.zeros(3), 1.0
    raise ValueError(f"noise_direction: no finite filter moves with {name!r}")


def predictor_errors(name: str, value: float, r: np.ndarray) -> np.ndarray:
    """One-step-ahead errors, on the host, of the fitted noise predictor `name`
    with parameter `value` on the residual `r`, from rest (`noise_filter`; the
    NumPy twin of `ar1_errors` and of `local_level_errors`, with $\\ell_0 = 0$,
    and of `fractional_errors`)."""
    if name == "fractional_d":
        return fractional_errors_numpy(r, value)
    f, g = noise_filter(name, value)
    return lfilter_numpy(f, np.array([1.0, g, 0.0]), r)


# The noise models of `fit_noise_family`, in its output order, and how many
# parameters each fits (the degrees of freedom taken from its innovation variance).
NOISE_MODELS = ("white", "ar1", "ar2", "arma11", "level", "fractional")
NOISE_PARAMETERS = {
    "white": 0,
    "ar1": 1,
    "ar2": 2,
    "arma11": 2,
    "level": 1,
    "fractional": 1,
}
# The MA coefficient c of ARMA(1,1) is fitted on this grid (|c| < 1: invertible),
# its AR pole by least squares given c.
MA_GRID = 39


def _lagged(x: Float[Array, " L"], k: int) -> Float[Array, " L"]:
    return jnp.concatenate([jnp.zeros(k, x.dtype), x[:-k]])


def _ar2(r: Float[Array, " L"], mask: Float[Array, " L"]) -> Float[Array, " 2"]:
    """Least-squares AR(2) coefficients (masked normal equations)."""
    x = jnp.stack([_lagged(r, 1), _lagged(r, 2)], axis=1) * mask[:, None]
    g = fixed_order_sum(x.T[:, None] * x.T[None]) + 1e-300 * jnp.eye(2)
    return jnp.linalg.solve(g, fixed_order_sum(x.T * (mask * r)[None]))


def _inverse_ma(r: Float[Array, " L"], c: Float[Array, ""]) -> Float[Array, " L"]:
    """$\\tilde r = r / (1 + c q^{-1})$, from rest."""

    def step(prev, rk):
        out = rk - c * prev
        return out, out

    return lax.scan(step, jnp.zeros((), r.dtype), r)[1]


def _arma11(
    r: Float[Array, " L"], mask: Float[Array, " L"]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """ARMA(1,1) $r_k = a r_{k-1} + e_k + c e_{k-1}$ by prediction error: for each
    $c$ on the grid the innovations $e = (1 - a q^{-1})\\tilde r$ are linear in
    $a$ (least squares, $|a| \\le 0.999$); the pair of least masked SSE."""
    cs = jnp.linspace(-0.95, 0.95, MA_GRID)

    def one(c):
        rt = _inverse_ma(r, c)
        prev = _lagged(rt, 1)
        den = jnp.maximum(fixed_order_sum(mask * prev**2), 1e-300)
        a = fixed_order_sum(mask * rt * prev) / den
        a = jnp.clip(a, -0.999, 0.999)
        return a, fixed_order_sum(mask * (rt - a * prev) ** 2)

    a, sse = jax.vmap(one)(cs)
    k = jnp.argmin(sse)
    return a[k], cs[k]


def _family_errors(r, a1, a2, arma, alpha, d):
    """One-step-ahead innovations of every model of `NOISE_MODELS` on `r`."""
    ar2 = r - a2[0] * _lagged(r, 1) - a2[1] * _lagged(r, 2)
    rt = _inverse_ma(r, arma[1])
    return jnp.stack(
        [
            r,
            ar1_errors(r, a1),
            ar2,
            rt - arma[0] * _lagged(rt, 1),
            local_level_errors(r, alpha),
            fractional_errors(r, d),
        ]
    )


class NoiseFamily(eqx.Module):
    """Every noise model of `NOISE_MODELS` fitted on one estimation residual."""

    ar1_pole: Float[Array, ""]
    ar2: Float[Array, " 2"]
    arma11: Float[Array, " 2"]  # (a, c)
    level_alpha: Float[Array, ""]
    fractional_d: Float[Array, ""]  # ARFIMA(0, d, 0): the flicker model
    e_est: Float[Array, "6 L"]  # innovations on the estimation record
    e_val: Float[Array, "6 L"]  # and on the validation record


@eqx.filter_jit
@ft.partial(jax.vmap, in_axes=(0, None, 0))
def fit_noise_family(
    r_est: Float[Array, " L"],
    m_est: Float[Array, " L"],
    r_val: Float[Array, " L"],
) -> NoiseFamily:
    """The models of `NOISE_MODELS` fitted on each row of `r_est` (masked by
    `m_est`) by prediction error, their innovations on `r_est` and `r_val`."""
    a1 = fit_ar1(r_est, m_est)
    a2 = _ar2(r_est, m_est)
    arma = jnp.stack(_arma11(r_est, m_est))
    alpha = fit_local_level(r_est, m_est)
    d, _ = fit_fractional(r_est, m_est)
    return NoiseFamily(
        a1,
        a2,
        arma,
        alpha,
        d,
        _family_errors(r_est, a1, a2, arma, alpha, d),
        _family_errors(r_val, a1, a2, arma, alpha, d),
    )


def noise_family_numpy(
    r_est: np.ndarray, r_val: np.ndarray
) -> tuple[dict, np.ndarray, np.ndarray]:
    """`fit_noise_family` on unpadded NumPy residuals `(rows, n_est)` and
    `(rows, n_val)` (padded to the record buckets and to a multiple of 8 rows):
    `(parameters per model, e_est (rows, 6, n_est), e_val (rows, 6, n_val))`."""
    rows, n_e = r_est.shape
    n_v = r_val.shape[1]
    n = bucket(max(n_e, n_v))
    padded = -(-rows // 8) * 8
    pe = np.zeros((padded, n))
    pe[:rows, :n_e] = r_est
    pv = np.zeros((padded, n))
    pv[:rows, :n_v] = r_val
    me = np.zeros(n)
    me[:n_e] = 1.0
    f = fit_noise_family(jnp.asarray(pe), jnp.asarray(me), jnp.asarray(pv))
    params = {
        "white": np.zeros((rows, 0)),
        "ar1": np.asarray(f.ar1_pole)[:rows, None],
        "ar2": np.asarray(f.ar2)[:rows],
        "arma11": np.asarray(f.arma11)[:rows],
        "level": np.asarray(f.level_alpha)[:rows, None],
        "fractional": np.asarray(f.fractional_d)[:rows, None],
    }
    return (
        params,
        np.asarray(f.e_est)[:rows, :, :n_e],
        np.asarray(f.e_val)[:rows, :, :n_v],
    )


def compile_in_background(lengths: Iterable[int]) -> threading.Thread:
    """Compile `fit_noise_models` for the records of these lengths on a thread.

    The candidate fits compile meanwhile (XLA releases the GIL while compiling), so
    the noise models, needed once the first case is fitted, are ready by then.
    """

    def run() -> None:
        for n in sorted({bucket(k) for k in lengths}):
            z = jnp.zeros(n)
            try:
                fit_noise_models(z, z, z)
            except Exception:  # noqa: BLE001 - a real call raises it where it matters
                return

    thread = threading.Thread(target=run, name="hamjax-noise-compile", daemon=True)
    thread.start()
    return thread
