"""A static map shifted vertically: $F(v) + c$ (the straight-line backlash borders)."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractStaticNonlinearity
from .identity import Identity


class Shifted(AbstractStaticNonlinearity):
    """$v \\mapsto F(v) + \\text{offset}$, with $F$ the identity by default.

    ```python
    >>> Shifted(offset=0.5)(jnp.array([0.0, 1.0]))
    Array([0.5, 1.5], dtype=float64)
    ```
    """

    offset: Float[Array, ""]
    inner: AbstractStaticNonlinearity

    def __init__(
        self,
        *,
        offset: Float[ArrayLike, ""],
        inner: AbstractStaticNonlinearity | None = None,
    ):
        self.offset = jnp.asarray(offset, dtype=float)
        self.inner = Identity() if inner is None else inner

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return self.inner(v) + self.offset
