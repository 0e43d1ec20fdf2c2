"""Continuous transfer function $G(s) = \\text{num}(s)/\\text{den}(s)$."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ..._checks import check_finite, concrete
from ..._fields import float_field
from ..._filters import companion, zoh_tf
from ._base import AbstractContinuousLinearBlock, rational_stable
from .state_space import DiscreteStateSpace


class ContinuousTransferFunction(AbstractContinuousLinearBlock):
    r"""$G(s) = \frac{\text{num}_0 s^m + \dots + \text{num}_m}
    {\text{den}_0 s^n + \dots + \text{den}_n}$, coefficients highest power first,
    proper ($m \le n$).

    Simulated exactly for inputs held between samples (`discretise(dt)`, the
    zero-order hold by the matrix exponential), or by diffrax for arbitrary
    inputs (`hamjax.simulate_diffrax`).
    """

    num: Float[Array, " m"] = float_field()
    den: Float[Array, " n"] = float_field()

    def __check_init__(self):
        if self.num.ndim != 1 or self.den.ndim != 1 or self.den.shape[0] < 1:
            raise ValueError(
                f"num and den must be 1-D and den non-empty; got {self.num.shape}, "
                f"{self.den.shape}"
            )
        if self.num.shape[0] > self.den.shape[0]:
            raise ValueError(
                "G(s) must be proper: deg num <= deg den; got "
                f"{self.num.shape[0] - 1} > {self.den.shape[0] - 1}"
            )
        den0 = concrete(self.den)
        if den0 is not None and den0[0] == 0:
            raise ValueError("the leading coefficient den[0] must be non-zero")
        check_finite("ContinuousTransferFunction.num", self.num)
        check_finite("ContinuousTransferFunction.den", self.den)

    @property
    def order(self) -> int:
        return self.den.shape[0] - 1

    def static_gain(self) -> Float[Array, ""]:
        return self.num[-1] / self.den[-1]

    def poles(self) -> np.ndarray:
        den = concrete(self.den)
        if den is None:
            raise ValueError("poles need concrete coefficients (not under jit)")
        return np.roots(den)

    def stable(self, *, xp=jnp) -> Bool[Array, ""]:
        return rational_stable(self.den, self.num, continuous=True, xp=xp)

    def scaled(self, gain) -> "ContinuousTransferFunction":
        return ContinuousTransferFunction(self.num * gain, self.den)

    def frequency_response(self, omega: Float[ArrayLike, " freq"]) -> Array:
        s = 1j * jnp.asarray(omega, dtype=float)
        return jnp.polyval(self.num, s) / jnp.polyval(self.den, s)

    def state_space(self) -> tuple[Array, Array, Array, Array]:
        """Controllable canonical form `(A, B, C, D)` (the `scipy.signal.tf2ss` one,
        `hamjax._filters.companion`)."""
        return companion(self.num, self.den)

    def discretise(self, dt: float) -> DiscreteStateSpace:
        """Exact zero-order-hold discretisation at sampling period `dt`."""
        if not dt > 0:
            raise ValueError(f"sampling period dt must be > 0; got {dt}")
        return DiscreteStateSpace(*zoh_tf(self.num, self.den, dt), dt=dt)
