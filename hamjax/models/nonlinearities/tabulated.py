"""A static map tabulated on a grid, linearly interpolated."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._checks import check_finite, check_strictly_increasing
from ..._fields import float_field
from ._base import AbstractStaticNonlinearity


class Tabulated(AbstractStaticNonlinearity):
    """$F$ given by its values `u` on a strictly increasing grid `v`, linearly
    interpolated between grid points and held constant beyond the ends.

    ```python
    >>> F = Tabulated(v=jnp.array([-1.0, 0.0, 1.0]), u=jnp.array([0.0, 1.0, 0.0]))
    >>> F(jnp.array([-2.0, -0.5, 0.5, 3.0]))
    Array([0. , 0.5, 0.5, 0. ], dtype=float64)
    ```
    """

    v: Float[Array, " grid"] = float_field()
    u: Float[Array, " grid"] = float_field()

    def __check_init__(self):
        if self.v.ndim != 1 or self.v.shape != self.u.shape:
            raise ValueError(
                "Tabulated needs 1-D `v` and `u` of the same length; got shapes "
                f"{self.v.shape} and {self.u.shape}"
            )
        if self.v.shape[0] < 2:
            raise ValueError("Tabulated needs at least two grid points")
        check_strictly_increasing("Tabulated.v", self.v)
        check_finite("Tabulated.u", self.u)

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return jnp.interp(v, self.v, self.u)
