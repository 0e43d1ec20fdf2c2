"""Abstract linear blocks."""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..._checks import concrete


def companion_roots(tail: Float[Array, " n"]) -> Array:
    r"""Roots of the monic polynomial $x^n + c_1 x^{n-1} + \dots + c_n$ with
    `tail` $= (c_1, \dots, c_n)$, as the eigenvalues of its companion matrix
    (traceable: the stability checks run under jit and vmap)."""
    n = tail.shape[0]
    companion = jnp.zeros((n, n), dtype=tail.dtype).at[0, :].set(-tail)
    if n > 1:
        companion = companion.at[1:, :-1].set(jnp.eye(n - 1))
    return jnp.linalg.eigvals(companion)


class AbstractLinearBlock(eqx.Module):
    """A stable, single-input single-output linear time-invariant block."""

    @abc.abstractmethod
    def static_gain(self) -> Float[Array, ""]:
        """$G(0)$ (continuous) or $G(1) = B(1)/A(1)$ (discrete)."""

    @abc.abstractmethod
    def poles(self) -> Array:
        """The poles (complex), computed from concrete coefficients."""

    @abc.abstractmethod
    def stable(self) -> Bool[Array, ""]:
        """Whether all poles are strictly inside the stability region and every
        coefficient is finite; traceable (under jit, a traced boolean)."""

    def is_stable(self) -> bool:
        """`stable()` of a block with concrete coefficients, as a Python bool
        (`ValueError` for traced ones: use `stable()` there)."""
        ok = concrete(self.stable())
        if ok is None:
            raise ValueError("is_stable needs concrete coefficients (not under jit)")
        return bool(ok)

    @abc.abstractmethod
    def scaled(self, gain) -> "AbstractLinearBlock":
        """The same block with its output multiplied by `gain`."""


class AbstractDiscreteLinearBlock(AbstractLinearBlock):
    """A linear block in discrete time (one step per sample)."""


class AbstractContinuousLinearBlock(AbstractLinearBlock):
    """A linear block in continuous time, simulated at a sampling period `dt`."""

    @abc.abstractmethod
    def frequency_response(self, omega: Float[Array, " freq"]) -> Array:
        """$G(j\\omega)$, complex."""
