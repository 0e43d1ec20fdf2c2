"""The identity map (a plant whose nonlinearity is absent)."""

from jaxtyping import Array, Float

from ._base import AbstractStaticNonlinearity


class Identity(AbstractStaticNonlinearity):
    """$F(v) = v$.

    ```python
    >>> Identity()(jnp.array([-1.0, 2.0]))
    Array([-1.,  2.], dtype=float64)
    ```
    """

    def __call__(self, v: Float[Array, "*shape"]) -> Float[Array, "*shape"]:
        return v
