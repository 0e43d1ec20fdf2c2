r"""Time-major batched simulation, for Monte Carlo throughput.

`vmap` of a per-realisation `lax.scan` is correct but slow on CPU; the form here
scans over time once, with the realisations as the vector axis inside the scan body
(input `(time, batch)`), fuses the nonlinearity into the same scan, keeps only
running summaries in the carry, and takes a static `unroll`. It equals the
summaries of `hamjax.simulate` (tested), which remains the definition. Seed 001's
(4.1) has its time-major form beside the reference, in
`identification/seed001/normalised_gradient_4_1.py`.
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
    check_unroll(unroll)
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


def check_unroll(unroll) -> None:
    """`unroll` of a time-major scan: an integer >= 1 (`ValueError` otherwise)."""
    if isinstance(unroll, bool) or not isinstance(unroll, int) or unroll < 1:
        raise ValueError(f"unroll must be an integer >= 1; got {unroll!r}")
