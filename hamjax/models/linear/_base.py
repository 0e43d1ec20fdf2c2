"""Abstract linear blocks."""

import abc

import equinox as eqx
from jaxtyping import Array, Float


class AbstractLinearBlock(eqx.Module):
    """A stable, single-input single-output linear time-invariant block."""

    @abc.abstractmethod
    def static_gain(self) -> Float[Array, ""]:
        """$G(0)$ (continuous) or $G(1) = B(1)/A(1)$ (discrete)."""

    @abc.abstractmethod
    def poles(self) -> Array:
        """The poles (complex), computed from concrete coefficients."""

    @abc.abstractmethod
    def is_stable(self) -> bool:
        """Whether all poles are strictly inside the stability region."""

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
