r"""Time-major batched forms of two hot loops, for Monte Carlo throughput.

`vmap` of a per-realisation `lax.scan` is correct but slow on CPU; the forms here
scan over time once, with the realisations as the vector axis inside the scan body
(input `(time, batch)`), fuse the nonlinearity into the same scan, keep only running
summaries in the carry, and take a static `unroll`. Each equals the per-realisation
reference it names (tested), which remains the definition.
"""

import jax
import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..models import (
    AbstractHysteresisNonlinearity,
    DiscreteTransferFunction,
    Hammerstein,
)


def _check_unroll(unroll) -> None:
    if isinstance(unroll, bool) or not isinstance(unroll, int) or unroll < 1:
        raise ValueError(f"unroll must be an integer >= 1; got {unroll!r}")


def _check_plant(plant: Hammerstein) -> DiscreteTransferFunction:
    if not isinstance(plant, Hammerstein):
        raise ValueError(f"plant must be a Hammerstein; got {type(plant).__name__}")
    if not isinstance(plant.linear, DiscreteTransferFunction):
        raise ValueError(
            "the fused simulation needs a DiscreteTransferFunction linear block; got "
            f"{type(plant.linear).__name__} (discretise it first)"
        )
    return plant.linear


def output_summary(
    plant: Hammerstein, v: Float[Array, " time"], *, unroll: int = 1
) -> dict[str, Float[Array, ""]]:
    r"""Mean, RMS and max $|w|$ of the noise-free output $w$ of `plant` driven by `v`.

    One `lax.scan` that steps the nonlinearity and the linear block (direct form II
    transposed) together, so no signal is stored; equals the summaries of
    `hamjax.simulate(plant, v)`.
    """
    return jax.tree.map(
        lambda x: x[0], output_summary_time_major(plant, v[:, None], unroll=unroll)
    )


def output_summary_time_major(
    plant: Hammerstein, v: Float[Array, "time batch"], *, unroll: int = 1
) -> dict[str, Float[Array, " batch"]]:
    """`output_summary` for a batch of inputs stored time-major, `(time, batch)`."""
    linear = _check_plant(plant)
    _check_unroll(unroll)
    if v.ndim != 2:
        raise ValueError(f"v must be (time, batch); got shape {v.shape}")
    nl = plant.nonlinearity
    b, a = linear._padded()
    n = linear.order
    hysteresis = isinstance(nl, AbstractHysteresisNonlinearity)
    s0 = jax.vmap(nl.init)(v[0]) if hysteresis else None
    zeros = jnp.zeros(v.shape[1], v.dtype)

    def step(carry, vk):
        s, z, total, squares, peak = carry
        if hysteresis:
            s, u = jax.vmap(nl.step)(s, vk)
        else:
            u = nl(vk)
        # Direct form II transposed, as DiscreteTransferFunction.response.
        y = b[0] * u + (z[0] if n > 0 else 0.0)
        if n > 0:
            shifted = jnp.concatenate([z[1:], zeros[None]], axis=0)
            z = shifted + b[1:, None] * u[None] - a[1:, None] * y[None]
        return (s, z, total + y, squares + y * y, jnp.maximum(peak, jnp.abs(y))), None

    z0 = jnp.zeros((max(n, 1), v.shape[1]), v.dtype)
    init = (s0, z0, zeros, zeros, zeros)
    (_, _, total, squares, peak), _ = lax.scan(step, init, v, unroll=unroll)
    T = v.shape[0]
    return {"mean": total / T, "rms": jnp.sqrt(squares / T), "max_abs": peak}


def normalised_gradient_time_major(
    y: Float[Array, "time batch"],
    g: Float[Array, "time q"],
    *,
    order: int,
    theta0: Float[Array, " p"],
    rho: float,
    unroll: int = 1,
) -> Float[Array, "batch p"]:
    r"""Final estimates of seed 001's (4.1a-b) for a batch of outputs, time-major.

    The regressor (3.8b) is $\Phi(t) = [-y(t-1) \dots -y(t-n),\ g(t)]$ where the
    input part $g(t)$ (the $v(t-i) P_j(v(t-i))$ columns, shape `(time, 4n)`) is the
    same for every realisation (a fixed excitation), so it is passed once. Equals
    `normalised_gradient(regressor(v, y_r), y_r, ...)[0]` for each column `y_r`.
    """
    if y.ndim != 2 or g.ndim != 2 or g.shape[0] != y.shape[0]:
        raise ValueError(f"need y (time, batch), g (time, q); got {y.shape}, {g.shape}")
    _check_unroll(unroll)
    n = int(order)
    if theta0.shape != (n + g.shape[1],):
        raise ValueError(
            f"theta0 must have {n + g.shape[1]} entries; got {theta0.shape}"
        )
    batch = y.shape[1]
    theta = jnp.broadcast_to(theta0[:, None], (theta0.shape[0], batch)).astype(y.dtype)
    lags = jnp.zeros((n, batch), y.dtype)
    g_norm2 = jnp.sum(g * g, axis=1)

    def step(carry, row):
        theta, lags = carry
        y_t, g_t, gg = row
        phi_y = -lags  # -y(t-1) .. -y(t-n), Eq. (3.8b)
        e = y_t - jnp.sum(phi_y * theta[:n], axis=0) - g_t @ theta[n:]  # Eq. (4.1b)
        gain = e / (1.0 + jnp.sum(phi_y * phi_y, axis=0) + gg)
        candidate = (
            theta
            + jnp.concatenate(
                [phi_y, jnp.broadcast_to(g_t[:, None], (g_t.shape[0], batch))], axis=0
            )
            * gain[None]
        )  # Eq. (4.1a)
        norm = jnp.sqrt(jnp.sum(candidate * candidate, axis=0))
        scale = jnp.where(norm > rho, rho / jnp.where(norm > 0, norm, 1.0), 1.0)
        theta = candidate * scale[None]  # Eq. (4.1a), projection on the ball
        lags = jnp.concatenate([y_t[None], lags[:-1]], axis=0)
        return (theta, lags), None

    (theta, _), _ = lax.scan(step, (theta, lags), (y, g, g_norm2), unroll=unroll)
    return theta.T
