"""Discrete transfer function $y = B(q^{-1}) / A(q^{-1})\\, u$ (seed 001 form)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ..._checks import check_finite, concrete
from ..._filters import df2t_step, filter_scan
from ..._types import Signal
from ._base import AbstractDiscreteLinearBlock, rational_stable


class DiscreteTransferFunction(AbstractDiscreteLinearBlock):
    r"""$A(q^{-1}) y(t) = B(q^{-1}) u(t)$ with

    $A = 1 + a_1 q^{-1} + \dots + a_n q^{-n}$ (so `a[0] = 1`) and
    $B = b_0 + b_1 q^{-1} + \dots$; a pure delay is `b[0] = 0`. `dt` is the
    sampling period in seconds (metadata; it does not change the response).

    The response is computed in direct form II transposed, so it equals
    `scipy.signal.lfilter(b, a, u)` from rest.
    """

    b: Float[Array, " nb"]
    a: Float[Array, " na"]
    dt: float | None = eqx.field(static=True, default=None)

    def __init__(
        self,
        b: Float[ArrayLike, " nb"],
        a: Float[ArrayLike, " na"],
        dt: float | None = None,
    ):
        self.b = jnp.asarray(b, dtype=float)
        self.a = jnp.asarray(a, dtype=float)
        self.dt = None if dt is None else float(dt)

    def __check_init__(self):
        if self.a.ndim != 1 or self.a.shape[0] < 1:
            raise ValueError(
                "denominator `a` must have a leading coefficient; got shape "
                f"{self.a.shape}"
            )
        if self.b.ndim != 1 or self.b.shape[0] < 1:
            raise ValueError(
                f"numerator `b` must be 1-D and non-empty; got {self.b.shape}"
            )
        a0 = concrete(self.a[0]) if concrete(self.a) is not None else None
        if a0 is not None and a0 != 1.0:
            raise ValueError(
                f"A(q^-1) must be monic: a[0] must be 1, got {float(a0)} "
                "(divide b and a by a[0])"
            )
        check_finite("DiscreteTransferFunction.a", self.a)
        check_finite("DiscreteTransferFunction.b", self.b)
        if self.dt is not None and not self.dt > 0:
            raise ValueError(f"sampling period dt must be > 0; got {self.dt}")

    @property
    def order(self) -> int:
        """$\\max(\\deg A, \\deg B)$ in $q^{-1}$: the state dimension."""
        return max(self.a.shape[0], self.b.shape[0]) - 1

    def _padded(self) -> tuple[Array, Array]:
        n = self.order + 1
        b = jnp.pad(self.b, (0, n - self.b.shape[0]))
        a = jnp.pad(self.a, (0, n - self.a.shape[0]))
        return b, a

    def static_gain(self) -> Float[Array, ""]:
        return jnp.sum(self.b) / jnp.sum(self.a)

    def poles(self) -> np.ndarray:
        a = concrete(self.a)
        if a is None:
            raise ValueError("poles need concrete coefficients (not under jit)")
        return np.roots(a) if a.shape[0] > 1 else np.zeros(0, complex)

    def stable(self, *, xp=jnp) -> Bool[Array, ""]:
        # A(q^-1) = 1 + a1 q^-1 + ...: its poles are the roots of z^n + a1 z^(n-1) + ...
        return rational_stable(self.a, self.b, continuous=False, xp=xp)

    def scaled(self, gain) -> "DiscreteTransferFunction":
        return DiscreteTransferFunction(self.b * gain, self.a, self.dt)

    def frequency_response(self, omega: Float[ArrayLike, " freq"]) -> Array:
        """$G(e^{j\\omega})$ at normalised frequencies `omega` (rad/sample)."""
        z1 = jnp.exp(-1j * jnp.asarray(omega, dtype=float))
        return jnp.polyval(self.b[::-1], z1) / jnp.polyval(self.a[::-1], z1)

    def zero_state(self, u: Float[Array, "*batch"]) -> Float[Array, " n *batch"]:
        return jnp.zeros((max(self.order, 1),) + jnp.shape(u), jnp.result_type(u))

    def step(self, state, u):
        """Direct form II transposed, one sample."""
        b, a = self._padded()
        return df2t_step(b, a, state, u)

    def response(self, u: Signal) -> Signal:
        """Output from rest for the input samples `u` (same as `lfilter(b, a, u)`)."""
        b, a = self._padded()
        if self.order == 0:
            return b[0] * u
        return filter_scan(b, a, u, self.zero_state(u[0]))[1]
