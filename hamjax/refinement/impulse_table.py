"""Seed 001 refinement for the input (5.1): $a$, $b$ and the four values $F(V_j)$.

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*. Under (5.1) the input takes only the values
$0, V_1, \\dots, V_4$ and $F(0) = 0$ (Eq. (3.2)), so $u = F(v)$ is a table of four
numbers: these, with $a$ and $b$ in the normalisation (3.10), are all the data
can identify.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._types import Params, Signal
from ._discrete import (
    AbstractDiscreteParametrisation,
    discrete_response,
    discrete_stable,
)
from .normalisation import normalise_b, sphere_coordinates, sphere_point


class ImpulseTableParametrisation(AbstractDiscreteParametrisation):
    """$\\theta = (a_1..a_n, \\delta_1..\\delta_{n-1}, F(V_1)..F(V_4))$, where
    $\\delta$ is a chart of $\\sum b_i^2 = 1$ at `b_ref` (Eq. (3.10)).

    Reported (`to_physical`): $(a_1..a_n, b_1..b_n, F(V_1)..F(V_4))$ with $b$ and
    $F$ normalised by (3.10).

    **Arguments:**

    - `levels`: $(V_1, \\dots, V_4)$ of (3.1).
    - `b_ref`: the point of the chart, usually the initial estimate of $b$
      (normalised here).
    """

    levels: Float[Array, " 4"]
    b_ref: Float[Array, " n"]

    def __init__(self, levels: Float[ArrayLike, " 4"], b_ref: Float[ArrayLike, " n"]):
        self.levels = jnp.asarray(levels, dtype=float)
        self.b_ref = normalise_b(jnp.asarray(b_ref, dtype=float))[0]

    def __check_init__(self):
        if self.levels.shape != (4,):
            raise ValueError(
                f"levels must be (V1, V2, V3, V4); got {self.levels.shape}"
            )
        if self.b_ref.ndim != 1 or self.b_ref.shape[0] < 1:
            raise ValueError(f"b_ref must be 1-D and non-empty; got {self.b_ref.shape}")

    @property
    def names(self) -> tuple[str, ...]:
        return self._ab_names() + tuple(f"F(V{j + 1})" for j in range(4))

    def table_input(self, f: Float[Array, " 4"], v: Signal) -> Signal:
        """$u = F(v)$ for $v \\in \\{0, V_1..V_4\\}$ (the nearest value is used)."""
        grid = jnp.concatenate([jnp.zeros(1), self.levels])
        index = jnp.argmin(jnp.abs(v[:, None] - grid[None, :]), axis=1)
        return jnp.concatenate([jnp.zeros(1), f])[index]

    def predict(self, theta: Params, v: Signal) -> Signal:
        a, delta, f = self._split(theta)
        b = sphere_point(self.b_ref, delta)
        # Eq. (3.6a-b): A y = B P(v) and P(v) = F(v) on {0, V1..V4}.
        return discrete_response(a, b, self.table_input(f, v))

    def to_physical(self, theta: Params) -> Float[Array, " n_physical"]:
        a, delta, f = self._split(theta)
        b, g = normalise_b(sphere_point(self.b_ref, delta))
        return jnp.concatenate([a, b, f * g])

    def from_physical(self, physical: Float[Array, " n_physical"]) -> Params:
        n = self.order
        a, b, f = physical[:n], physical[n : 2 * n], physical[2 * n :]
        # Accept any scale of b; the chart keeps the sign of b_ref, so align first.
        g = jnp.linalg.norm(b) * jnp.where(jnp.dot(b, self.b_ref) < 0, -1.0, 1.0)
        return jnp.concatenate([a, sphere_coordinates(self.b_ref, b / g), f * g])

    def is_valid(self, theta: Params) -> Bool[Array, ""]:
        return discrete_stable(self._split(theta)[0])
