"""A hysteresis operator with its output scaled: $k F[v]$ for any sign of $k$."""

from typing import Any

import equinox as eqx
from jaxtyping import Array, Float

from ..._fields import float_field
from ._base import AbstractHysteresisNonlinearity


class OutputScaled(AbstractHysteresisNonlinearity):
    """$v \\mapsto \\text{gain} \\cdot F[v]$ for a hysteresis operator $F$.

    Scaling the borders of a backlash by a negative gain would swap which border
    is met first, so a negative $k$ (seed 000's $kF$ with $G(0) < 0$) is applied
    to the output of the unchanged operator instead.
    """

    inner: AbstractHysteresisNonlinearity = eqx.field(kw_only=True)
    gain: Float[Array, ""] = float_field(kw_only=True)

    def init(self, v0: Float[Array, ""]) -> Any:
        return self.inner.init(v0)

    def step(self, state: Any, v: Float[Array, ""]) -> tuple[Any, Float[Array, ""]]:
        state, u = self.inner.step(state, v)
        return state, self.gain * u
