"""Two-segment piecewise-linear map with preload and dead zone (seed 001, Fig. 2)."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._checks import concrete
from ..._fields import float_field
from ._base import AbstractStaticNonlinearity


# The six numbers of Fig. 2 of seed 001, in the order every user of them keeps.
PARAMETERS = ("k1", "k2", "d1", "d2", "l1", "l2")


def piecewise_linear_map(v, k1, k2, d1, d2, l1, l2, *, xp=jnp):
    """Fig. 2 of seed 001 on `v` from its six numbers (the one implementation:
    `PiecewiseLinear`, the refinement, the diagnosis and the blind cases call it).

    `xp=numpy` evaluates it on the host with NumPy, elementwise and so bitwise the
    same as the traced version's operations.
    """
    upper = k1 * (v - d1) + l1
    lower = k2 * (v - d2) + l2
    return xp.where(v > d1, upper, xp.where(v < d2, lower, 0.0))


class PiecewiseLinear(AbstractStaticNonlinearity):
    r"""The seed-001 nonlinearity of Fig. 2, in the signed convention:

    $$F(v) = \begin{cases} k_1 (v - d_1) + l_1 & v > d_1 \\
    0 & d_2 \le v \le d_1 \\ k_2 (v - d_2) + l_2 & v < d_2 \end{cases}$$

    with $d_2 \le 0 \le d_1$. A dead zone has $l_1 = l_2 = 0$; a preload has
    $d_1 = d_2 = 0$ and jumps $l_1 > 0 > l_2$ at the origin.

    ```python
    >>> F = PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0)
    >>> F(jnp.array([-6.0, -3.0, 0.0, 3.0, 6.0]))
    Array([-10.,  -4.,   0.,   3.,   6.], dtype=float64)
    ```
    """

    k1: Float[Array, ""] = float_field(kw_only=True)
    k2: Float[Array, ""] = float_field(kw_only=True)
    d1: Float[Array, ""] = float_field(kw_only=True, default=0.0)
    d2: Float[Array, ""] = float_field(kw_only=True, default=0.0)
    l1: Float[Array, ""] = float_field(kw_only=True, default=0.0)
    l2: Float[Array, ""] = float_field(kw_only=True, default=0.0)

    def __check_init__(self):
        for name in PARAMETERS:
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(f"PiecewiseLinear.{name} must be a scalar")
        d1, d2 = concrete(self.d1), concrete(self.d2)
        if d1 is not None and d2 is not None and (d2 > 0.0 or d1 < 0.0):
            raise ValueError(
                "PiecewiseLinear needs d2 <= 0 <= d1 (seed 001, Fig. 2); got "
                f"d1={float(d1)}, d2={float(d2)}"
            )

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return piecewise_linear_map(
            v, self.k1, self.k2, self.d1, self.d2, self.l1, self.l2
        )

    @property
    def dead_zone_width(self) -> Float[Array, ""]:
        """$d_1 - d_2$."""
        return self.d1 - self.d2

    def replace(self, **kwargs) -> "PiecewiseLinear":
        """A copy with some of `k1, k2, d1, d2, l1, l2` changed."""
        fields = {n: getattr(self, n) for n in PARAMETERS}
        fields.update(kwargs)
        return PiecewiseLinear(**fields)
