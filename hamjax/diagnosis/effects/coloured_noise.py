"""`coloured_noise`: $y = w + e'$ with $e'$ coloured, seen through prediction.

An AR(1) process: $e'_k = a e'_{k-1} + \\varepsilon_k$; the one-step-ahead
predictor of the residual is $a r_{k-1}$, so the gap is the RMS of
$r_k - a r_{k-1}$. $a = 0$ is neutral (white noise, predictor 0).

Coloured noise off the AR(1) form (ARMA, flicker) is often predicted better by a
local level of high gain $\\alpha > 1/2$, whose innovations are mostly coloured
(`effects/drift.py` derives the white share $1 - \\alpha$); that predictor is this
class's too, and `noise_fit.fit_noise_models` takes whichever of the class's
predictors (these two and the flicker one below) fits the estimation record best.

**Flicker noise.** A $1/f^\\beta$ spectrum (flicker, $\\beta$ near 1: resistors,
semiconductor sensors, many drifts of electronics) is neither: its memory decays
as a power of the lag, not geometrically. Its model is fractional integration,
$(1 - q^{-1})^d e'_k = \\varepsilon_k$ (ARFIMA(0, d, 0), spectrum
$\\propto |2 \\sin(\\omega/2)|^{-2d}$, so $d = \\beta / 2$), whose one-step
predictor leaves $\\varepsilon = \\Pi_d(q) r$ with the AR($\\infty$) weights
$\\pi_0 = 1$, $\\pi_k = \\pi_{k-1} (k - 1 - d) / k$ (truncated at the record's
start: from rest, as the other predictors). One parameter, as the others, so
the class takes whichever of the three has the least estimation SSE; $d = 0$ is
neutral. It has no white part, as the contract's `coloured_noise`; a trend in
white noise (`drift`) keeps a white floor that it cannot follow, so there the
local level of `effects/drift.py` predicts better (and the other way round on
flicker noise, where no geometric memory fits it).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float
from scipy import signal

from ..._linalg import fixed_order_sum
from ._base import AbstractEffect


def ar1_errors(
    r: Float[Array, " time"], pole: Float[Array, ""]
) -> Float[Array, " time"]:
    """One-step-ahead errors $r_k - a r_{k-1}$ (with $r_{-1} = 0$)."""
    prev = jnp.concatenate([jnp.zeros(1, r.dtype), r[:-1]])
    return r - pole * prev


def fit_ar1(r: Float[Array, " time"], mask: Float[Array, " time"]) -> Float[Array, ""]:
    """Least-squares AR(1) coefficient on the masked residual, clipped to $[0, 0.999]$."""
    prev = jnp.concatenate([jnp.zeros(1, r.dtype), r[:-1]])
    den = jnp.maximum(fixed_order_sum(mask * prev**2), 1e-300)
    a = fixed_order_sum(mask * r * prev) / den
    return jnp.clip(a, 0.0, 0.999)


# The fractional order's grid: k / 20 in (0, 1). d = 1 (differencing) is left
# out: it is the local level of gain 1 (`effects/drift.py`), already a predictor
# of this class
FRACTIONAL_GRID = 20


@functools.cache
def _orders() -> Array:
    # built on first use, not at import (`effects/drift.py`'s `_alphas` says why)
    with jax.ensure_compile_time_eval():
        return jnp.arange(1, FRACTIONAL_GRID) / FRACTIONAL_GRID


def fractional_weights(d, n: int, xp=jnp):
    """The AR($\\infty$) weights $\\pi_0 \\ldots \\pi_{n-1}$ of
    $(1 - q^{-1})^d$ (module docstring), in `xp` (`jax.numpy` or `numpy`)."""
    k = xp.arange(1, n, dtype=float)
    return xp.concatenate([xp.ones(1), xp.cumprod((k - 1 - d) / k)])


def fractional_errors(
    r: Float[Array, " time"], d: Float[Array, ""]
) -> Float[Array, " time"]:
    """One-step-ahead errors $\\Pi_d(q) r$ of the fractional predictor, from rest
    (a linear convolution by FFT)."""
    n = r.shape[0]
    size = 2 * n
    pi = fractional_weights(d, n)
    return jnp.fft.irfft(jnp.fft.rfft(r, size) * jnp.fft.rfft(pi, size), size)[:n]


def fractional_errors_numpy(r: np.ndarray, d: float) -> np.ndarray:
    """`fractional_errors` on the host (the twin of `predictor_errors`' filters)."""
    n = r.shape[-1]
    return signal.oaconvolve(r, fractional_weights(d, n, np), axes=-1)[..., :n]


def fit_fractional(
    r: Float[Array, " time"], mask: Float[Array, " time"]
) -> tuple[Array, Array]:
    """The order $d$ of least masked one-step SSE on the grid over $(0, 1)$, and
    that SSE: `(d, sse)`."""
    sse = jax.vmap(lambda d: fixed_order_sum(mask * fractional_errors(r, d) ** 2))(
        _orders()
    )
    i = jnp.argmin(sse)
    return _orders()[i], sse[i]


class ColouredNoiseEffect(AbstractEffect):
    """Coloured output noise: AR(1), a high-gain level or flicker (noise-model
    effect, not simulated)."""

    name = "coloured_noise"
    deterministic = False
