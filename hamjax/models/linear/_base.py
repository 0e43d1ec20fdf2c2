"""Abstract linear blocks."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..._checks import concrete


def companion_roots(tail: Float[Array, " n"], *, xp=jnp) -> Array:
    r"""Roots of the monic polynomial $x^n + c_1 x^{n-1} + \dots + c_n$ with
    `tail` $= (c_1, \dots, c_n)$, as the eigenvalues of its companion matrix.

    Traceable with `xp = jax.numpy` (the stability checks run under jit and vmap);
    `xp = numpy` is the same computation on the host, for concrete coefficients
    (no small XLA programs compiled per shape).
    """
    n = tail.shape[0]
    companion = xp.concatenate([-tail[None, :], xp.eye(n - 1, n)], axis=0)
    return xp.linalg.eigvals(companion)


def rational_stable(den, num, *, continuous: bool, xp=jnp) -> Bool[Array, ""]:
    r"""`stable()` of a rational block from its denominator `den` (highest power of
    $s$, or of $z$, first) and numerator `num`: every coefficient finite and every
    root of `den` in the stability region, $\mathrm{Re}\,p < 0$ (`continuous`) or
    $|p| < 1$."""
    den, num = xp.asarray(den), xp.asarray(num)
    finite = xp.all(xp.isfinite(den)) & xp.all(xp.isfinite(num))
    if den.shape[0] == 1:
        return finite
    roots = companion_roots(den[1:] / den[0], xp=xp)
    inside = roots.real < 0.0 if continuous else xp.abs(roots) < 1.0
    return xp.all(inside) & finite


class AbstractLinearBlock(eqx.Module):
    """A stable, single-input single-output linear time-invariant block."""

    @abc.abstractmethod
    def static_gain(self) -> Float[Array, ""]:
        """$G(0)$ (continuous) or $G(1) = B(1)/A(1)$ (discrete)."""

    @abc.abstractmethod
    def poles(self) -> Array:
        """The poles (complex), computed from concrete coefficients."""

    @abc.abstractmethod
    def stable(self, *, xp=jnp) -> Bool[Array, ""]:
        """Whether all poles are strictly inside the stability region and every
        coefficient is finite; traceable (under jit, a traced boolean). `xp=numpy`
        computes it on the host (concrete coefficients only)."""

    def is_stable(self) -> bool:
        """`stable()` of a block with concrete coefficients, as a Python bool
        computed on the host (`ValueError` for traced ones: use `stable()`)."""
        arrays = [x for x in jax.tree.leaves(self) if eqx.is_array(x)]
        if any(concrete(x) is None for x in arrays):
            raise ValueError("is_stable needs concrete coefficients (not under jit)")
        return bool(self.stable(xp=np))

    @abc.abstractmethod
    def scaled(self, gain) -> "AbstractLinearBlock":
        """The same block with its output multiplied by `gain`."""


class AbstractDiscreteLinearBlock(AbstractLinearBlock):
    """A linear block in discrete time (one step per sample).

    `step` is the one sample of the block that `response` scans and that the
    time-major simulation (`hamjax.simulation.time_major`) runs for a batch: the
    input `u_k` may carry batch axes, the state then has them after its own axis.
    """

    @abc.abstractmethod
    def zero_state(self, u: Float[Array, "*batch"]) -> Float[Array, " n *batch"]:
        """The state at rest, for inputs shaped (and typed) like `u`."""

    @abc.abstractmethod
    def step(
        self, state: Float[Array, " n *batch"], u: Float[Array, "*batch"]
    ) -> tuple[Float[Array, " n *batch"], Float[Array, "*batch"]]:
        """One sample: `(state, u_k) -> (next state, y_k)`."""


class AbstractContinuousLinearBlock(AbstractLinearBlock):
    """A linear block in continuous time, simulated at a sampling period `dt`."""

    @abc.abstractmethod
    def frequency_response(self, omega: Float[Array, " freq"]) -> Array:
        """$G(j\\omega)$, complex."""
