"""Discrete state-space block $x_{k+1} = A x_k + B u_k$, $y_k = C x_k + D u_k$."""

import equinox as eqx
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ..._checks import concrete
from ..._filters import outer
from ..._types import Signal
from ._base import AbstractDiscreteLinearBlock


class DiscreteStateSpace(AbstractDiscreteLinearBlock):
    """Single-input single-output discrete state space, from rest ($x_0 = 0$)."""

    A: Float[Array, "n n"]
    B: Float[Array, "n 1"]
    C: Float[Array, "1 n"]
    D: Float[Array, "1 1"]
    dt: float | None = eqx.field(static=True, default=None)

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike, D: ArrayLike, dt=None):
        self.A = jnp.asarray(A, dtype=float)
        self.B = jnp.asarray(B, dtype=float).reshape(-1, 1)
        self.C = jnp.asarray(C, dtype=float).reshape(1, -1)
        self.D = jnp.asarray(D, dtype=float).reshape(1, 1)
        self.dt = None if dt is None else float(dt)

    def __check_init__(self):
        n = self.A.shape[0]
        if self.A.shape != (n, n) or self.B.shape != (n, 1) or self.C.shape != (1, n):
            raise ValueError(
                f"inconsistent state-space shapes A{self.A.shape} B{self.B.shape} "
                f"C{self.C.shape}"
            )

    def static_gain(self) -> Float[Array, ""]:
        n = self.A.shape[0]
        x = jnp.linalg.solve(jnp.eye(n) - self.A, self.B)
        return (self.C @ x + self.D)[0, 0]

    def poles(self) -> np.ndarray:
        A = concrete(self.A)
        if A is None:
            raise ValueError("poles need concrete matrices (not under jit)")
        return np.linalg.eigvals(A)

    def stable(self, *, xp=jnp) -> Bool[Array, ""]:
        A, B, C = (xp.asarray(m) for m in (self.A, self.B, self.C))
        finite = (
            xp.all(xp.isfinite(A)) & xp.all(xp.isfinite(B)) & xp.all(xp.isfinite(C))
        )
        return xp.all(xp.abs(xp.linalg.eigvals(A)) < 1.0) & finite

    def scaled(self, gain) -> "DiscreteStateSpace":
        return DiscreteStateSpace(self.A, self.B, self.C * gain, self.D * gain, self.dt)

    def zero_state(self, u: Float[Array, "*batch"]) -> Float[Array, " n *batch"]:
        return jnp.zeros((self.A.shape[0],) + jnp.shape(u), jnp.result_type(u))

    def step(self, state, u):
        r"""$x \leftarrow A x + B u_k$, $y_k = C x + D u_k$."""
        return _ss_step(self._vectors(), state, u)

    def _vectors(self):
        return self.A, self.B[:, 0], self.C[0], self.D[0, 0]

    def response(self, u: Signal) -> Signal:
        """Output from rest for the input samples `u`."""
        abcd = self._vectors()
        _, y = lax.scan(lambda x, uk: _ss_step(abcd, x, uk), self.zero_state(u[0]), u)
        return y


def _ss_step(abcd, x, u):
    A, B, c, d = abcd
    return A @ x + outer(B, u), c @ x + d * u
