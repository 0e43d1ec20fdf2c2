"""A static map shifted vertically: $F(v) + c$ (the straight-line backlash borders)."""

import equinox as eqx
from jaxtyping import Array, Float

from ..._fields import float_field
from ._base import AbstractStaticNonlinearity
from .identity import Identity


class Shifted(AbstractStaticNonlinearity):
    """$v \\mapsto F(v) + \\text{offset}$, with $F$ the identity by default.

    ```python
    >>> Shifted(offset=0.5)(jnp.array([0.0, 1.0]))
    Array([0.5, 1.5], dtype=float64)
    ```
    """

    offset: Float[Array, ""] = float_field(kw_only=True)
    inner: AbstractStaticNonlinearity = eqx.field(
        kw_only=True, default_factory=Identity
    )

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return self.inner(v) + self.offset
