"""`coloured_noise`: $y = w + e'$ with $e'$ an AR(1) process, seen through prediction.

$e'_k = a e'_{k-1} + \\varepsilon_k$; the one-step-ahead predictor of the residual is
$a r_{k-1}$, so the gap is the RMS of $r_k - a r_{k-1}$. $a = 0$ is neutral (white
noise, predictor 0).

Coloured noise off the AR(1) form (ARMA, flicker) is often predicted better by a
local level of high gain $\\alpha > 1/2$, whose innovations are mostly coloured
(`effects/drift.py` derives the white share $1 - \\alpha$); that predictor is this
class's too, and `noise_fit.fit_noise_models` takes whichever of the two fits the
estimation record better.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

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
    a = jnp.sum(mask * r * prev) / jnp.maximum(jnp.sum(mask * prev**2), 1e-300)
    return jnp.clip(a, 0.0, 0.999)


class ColouredNoiseEffect(AbstractEffect):
    """AR(1) output noise (noise-model effect, not simulated)."""

    name = "coloured_noise"
    deterministic = False
