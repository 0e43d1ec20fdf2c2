"""`drift`: $y = w + e + $ a slow trend, seen through one-step-ahead prediction.

The trend (a ramp or a random walk) does not repeat between experiments, so it
cannot be simulated on validation data; it is modelled as a local level
$\\ell_{k+1} = \\ell_k + \\alpha (r_k - \\ell_k)$ tracked on the residual $r$, and
the gap is the RMS of the one-step-ahead prediction error $r_k - \\ell_k$.
$\\alpha = 0$ (and $\\ell_0 = 0$) is neutral: the white-noise predictor $\\hat r = 0$.

**Drift keeps a white part.** The contract's drift is a slow trend *plus* the
white measurement noise $e$; its `coloured_noise` has no white part. For a
random-walk level seen in white noise of variance $\\sigma_e^2$ the steady-state
Kalman predictor is the local level above with gain
$\\alpha = P / (P + \\sigma_e^2)$, $P$ the predicted level variance
($P^2 = \\sigma_\\eta^2 (P + \\sigma_e^2)$), and its innovation variance is
$F = P + \\sigma_e^2 = \\sigma_e^2 / (1 - \\alpha)$: $1 - \\alpha$ is the white
part's share of what the predictor leaves. `drift` is the local level whose white
part is at least half of it, $\\alpha \\le$ `MAX_DRIFT_GAIN` $= 1/2$; a larger
gain says the residual is mostly coloured, and that predictor belongs to
`coloured_noise` (`effects/coloured_noise.py`).
"""

import functools

import jax
import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._linalg import fixed_order_sum
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


MAX_DRIFT_GAIN = 0.5  # module docstring: the white part at least half the innovations


def _level_sse(r: Float[Array, " time"], mask: Float[Array, " time"]) -> Array:
    """The masked prediction-error energy at each gain of the grid."""
    return jax.vmap(lambda a: fixed_order_sum(mask * local_level_errors(r, a) ** 2))(
        _alphas()
    )


def fit_local_level(
    r: Float[Array, " time"], mask: Float[Array, " time"]
) -> Float[Array, ""]:
    """$\\alpha$ minimising the masked prediction-error energy (grid over $[0, 1]$)."""
    return _alphas()[jnp.argmin(_level_sse(r, mask))]


def fit_split_local_level(
    r: Float[Array, " time"], mask: Float[Array, " time"]
) -> tuple[Array, Array, Array, Array]:
    """From one pass over the grid: the drift gain ($\\alpha \\le$
    `MAX_DRIFT_GAIN`) and the gain of the level above it (a `coloured_noise`
    predictor), each with its masked prediction-error energy:
    `(drift_alpha, drift_sse, high_alpha, high_sse)`."""
    alphas, sse = _alphas(), _level_sse(r, mask)
    low = alphas <= MAX_DRIFT_GAIN
    i = jnp.argmin(jnp.where(low, sse, jnp.inf))
    j = jnp.argmin(jnp.where(low, jnp.inf, sse))
    return alphas[i], sse[i], alphas[j], sse[j]


class DriftEffect(AbstractEffect):
    """Local-level trend on the output (noise-model effect, not simulated)."""

    name = "drift"
    deterministic = False
