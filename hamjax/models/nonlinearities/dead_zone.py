"""A dead zone: the input is lost inside a band around zero."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._checks import concrete
from ._base import AbstractBandNonlinearity


class DeadZone(AbstractBandNonlinearity):
    """$F(v) = v - \\text{upper}$ above `upper`, $v - \\text{lower}$ below `lower`,
    and $0$ in between (`lower <= 0 <= upper`; unit slopes).

    ```python
    >>> DeadZone(lower=-1.0, upper=0.5)(jnp.array([-2.0, 0.0, 1.0]))
    Array([-1. ,  0. ,  0.5], dtype=float64)
    ```
    """

    @classmethod
    def symmetric(cls, width: Float[ArrayLike, ""]) -> "DeadZone":
        """The contract's `sign(v) max(|v| - width, 0)`."""
        return cls(lower=-jnp.asarray(width, float), upper=jnp.asarray(width, float))

    def __check_init__(self):
        lo, up = concrete(self.lower), concrete(self.upper)
        if lo is not None and up is not None and not (lo <= 0.0 <= up):
            raise ValueError(f"DeadZone needs lower <= 0 <= upper; got {lo}, {up}")

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return jnp.where(
            v > self.upper,
            v - self.upper,
            jnp.where(v < self.lower, v - self.lower, 0.0),
        )
