"""Sampled simulation of Hammerstein plants: `lax.scan`, exact ZOH in continuous time."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._checks import check_finite, concrete
from .._types import Signal
from ..models import (
    AbstractLinearBlock,
    ContinuousTransferFunction,
    DiscreteStateSpace,
    DiscreteTransferFunction,
    Hammerstein,
    apply_nonlinearity,
)


def check_stable(linear: AbstractLinearBlock, what: str = "the linear block") -> None:
    """Raise `ValueError` if a concrete `linear` block is unstable."""
    try:
        stable = linear.is_stable()
    except ValueError:  # traced coefficients (under jit): nothing to check here
        return
    if not stable:
        poles = ", ".join(f"{p:.4g}" for p in linear.poles())
        region = (
            "|p| < 1"
            if not isinstance(linear, ContinuousTransferFunction)
            else "Re p < 0"
        )
        raise ValueError(f"{what} is unstable: poles {poles} (need {region})")


def linear_response(
    linear: AbstractLinearBlock, u: Signal, *, dt: float | None = None
) -> Signal:
    """Response from rest of a linear block to the samples `u`.

    A continuous block is simulated exactly for `u` held over each
    $[t_k, t_{k+1})$ (zero-order hold, matrix exponential): $y_k = C x(t_k) + D u_k$.

    **Arguments:**

    - `linear`: discrete or continuous block.
    - `u`: input samples, shape `(time,)`.
    - `dt`: sampling period (s); required for a continuous block.
    """
    return discrete_block(linear, dt=dt).response(u)


def discrete_block(
    linear: AbstractLinearBlock, *, dt: float | None
) -> DiscreteTransferFunction | DiscreteStateSpace:
    """The discrete block that simulates `linear` at sampling period `dt`: a
    continuous one discretised by zero-order hold, a discrete one itself (its own
    `dt`, when it has one, must be `dt`)."""
    if isinstance(linear, ContinuousTransferFunction):
        if dt is None:
            raise ValueError("a continuous linear block needs the sampling period `dt`")
        return linear.discretise(dt)
    if isinstance(linear, DiscreteTransferFunction | DiscreteStateSpace):
        own = linear.dt
        if dt is not None and own is not None and abs(dt - own) > 1e-9 * own:
            raise ValueError(
                f"the data are sampled at dt = {dt:g} s but the discrete linear "
                f"block has dt = {own:g} s"
            )
        return linear
    raise TypeError(f"unsupported linear block {type(linear).__name__}")


def simulate(
    plant: Hammerstein,
    v: Float[Array, " time"],
    *,
    dt: float | None = None,
    allow_unstable: bool = False,
) -> Signal:
    """Noise-free output $w$ of `plant` driven by the samples `v`, from rest.

    **Arguments:**

    - `plant`: a `Hammerstein` plant.
    - `v`: input samples, shape `(time,)`; must be finite.
    - `dt`: sampling period in seconds (required for continuous linear blocks).
    - `allow_unstable`: skip the stability check (it is made when the
      coefficients are concrete; under `jit` it is skipped).

    **Returns:** $w$, shape `(time,)`. Add noise with `hamjax.add_noise`.

    **Raises:** `ValueError` for a non-1-D or non-finite `v`, a missing `dt`, or an
    unstable linear block.
    """
    v = jnp.asarray(v, dtype=float)
    if v.ndim != 1:
        raise ValueError(f"input `v` must be 1-D (time,); got shape {v.shape}")
    if concrete(v) is not None:
        # NumPy on the concrete value: a jnp test would be staged out (a tracer)
        # when `v` is a constant closed over by a jitted function.
        check_finite("input `v`", v)
    else:
        v = eqx.error_if(v, ~jnp.all(jnp.isfinite(v)), "input `v` contains NaN or inf")
    if not allow_unstable:
        check_stable(plant.linear, "the plant's linear block")
    u = apply_nonlinearity(plant.nonlinearity, v)
    return linear_response(plant.linear, u, dt=dt)
