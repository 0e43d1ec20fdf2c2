"""A static map scaled at its output: $k F(v)$."""

import equinox as eqx
from jaxtyping import Array, Float

from ..._fields import float_field
from ._base import AbstractStaticNonlinearity


class Scaled(AbstractStaticNonlinearity):
    """$v \\mapsto \\text{gain} \\cdot F(v)$ (the $kF$ of seed 000's normalisation).

    ```python
    >>> Scaled(inner=Identity(), gain=2.0)(jnp.array([1.0]))
    Array([2.], dtype=float64)
    ```
    """

    inner: AbstractStaticNonlinearity = eqx.field(kw_only=True)
    gain: Float[Array, ""] = float_field(kw_only=True)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return self.gain * self.inner(v)
