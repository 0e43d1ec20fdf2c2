"""Abstract nonlinearities: static (memoryless) maps and hysteresis state machines."""

import abc
from typing import Any, TypeVar

import equinox as eqx
import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree

from ..._fields import float_field
from ..._types import Signal


_State = TypeVar("_State", bound=PyTree)


class AbstractNonlinearity(eqx.Module):
    """Any input nonlinearity $u = F[v]$ of a Hammerstein plant."""


class AbstractStaticNonlinearity(AbstractNonlinearity):
    """A memoryless map $u(t) = F(v(t))$, applied elementwise."""

    @abc.abstractmethod
    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        """Apply the map elementwise."""


class AbstractBandNonlinearity(AbstractStaticNonlinearity):
    """A static map set by a band `[lower, upper]` of the input (keyword-only,
    stored as float arrays)."""

    lower: Float[Array, ""] = float_field(kw_only=True)
    upper: Float[Array, ""] = float_field(kw_only=True)


class AbstractHysteresisNonlinearity(AbstractNonlinearity):
    """An operator with memory, written as a pure state machine run by `lax.scan`."""

    @abc.abstractmethod
    def init(self, v0: Float[Array, ""]) -> Any:
        """Initial state for a signal whose first sample is `v0`."""

    @abc.abstractmethod
    def step(self, state: Any, v: Float[Array, ""]) -> tuple[Any, Float[Array, ""]]:
        """Advance one sample: `(state, v) -> (state, u)`."""


def apply_nonlinearity(
    nonlinearity: AbstractNonlinearity, v: Signal, *, state: Any = None
) -> Signal:
    """Apply `nonlinearity` to the sampled signal `v`.

    **Arguments:**

    - `nonlinearity`: a static map or a hysteresis operator.
    - `v`: the input samples, shape `(time,)`.
    - `state`: for hysteresis operators, the state before `v[0]`; defaults to
      `nonlinearity.init(v[0])`.

    **Returns:** the output samples $u$, shape `(time,)`.
    """
    v = jnp.asarray(v)
    if v.ndim != 1:
        raise ValueError(f"`v` must be a 1-D signal; got shape {v.shape}")
    if isinstance(nonlinearity, AbstractStaticNonlinearity):
        return nonlinearity(v)
    if isinstance(nonlinearity, AbstractHysteresisNonlinearity):
        if state is None:
            state = nonlinearity.init(v[0])
        _, u = lax.scan(lambda s, x: nonlinearity.step(s, x), state, v)
        return u
    raise TypeError(
        f"expected a hamjax nonlinearity; got {type(nonlinearity).__name__}"
    )
