"""`drift`: $y = w + e + $ a slow trend, seen through one-step-ahead prediction.

The trend (a ramp or a random walk) does not repeat between experiments, so it
cannot be simulated on validation data; it is modelled as a local level
$\\ell_{k+1} = \\ell_k + \\alpha (r_k - \\ell_k)$ tracked on the residual $r$, and
the gap is the RMS of the one-step-ahead prediction error $r_k - \\ell_k$.
$\\alpha = 0$ (and $\\ell_0 = 0$) is neutral: the white-noise predictor $\\hat r = 0$.
"""

import functools

import jax
import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect


@functools.cache
def _alphas() -> Array:
    # built on first use, not at import: an array at import time would start JAX's
    # backend (fixing its flags, e.g. the device count) before the caller chose them;
    # evaluated eagerly even when first called under `jit`, so no tracer is cached
    with jax.ensure_compile_time_eval():
        return jnp.concatenate([jnp.array([0.0]), jnp.geomspace(1e-3, 1.0, 48)])


def local_level_errors(
    r: Float[Array, " time"], alpha: Float[Array, ""]
) -> Float[Array, " time"]:
    """One-step-ahead errors $r_k - \\ell_k$ of the local-level predictor."""

    def step(level, rk):
        return level + alpha * (rk - level), rk - level

    _, err = lax.scan(step, jnp.zeros((), r.dtype), r)
    return err


def fit_local_level(
    r: Float[Array, " time"], mask: Float[Array, " time"]
) -> Float[Array, ""]:
    """$\\alpha$ minimising the masked prediction-error energy (grid over $[0, 1]$)."""
    alphas = _alphas()
    sse = jax.vmap(lambda a: jnp.sum(mask * local_level_errors(r, a) ** 2))(alphas)
    return alphas[jnp.argmin(sse)]


class DriftEffect(AbstractEffect):
    """Local-level trend on the output (noise-model effect, not simulated)."""

    name = "drift"
    deterministic = False
