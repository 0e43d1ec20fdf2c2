"""The interface between a model structure and `refine` / the Cramér-Rao bound."""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._types import Params, Signal


class AbstractParametrisation(eqx.Module):
    """A model structure with free parameters $\\theta$ (identifiable: any
    normalisation is built in) and reported, physical parameters.

    `predict(theta, v)` is the noise-free output, differentiable in `theta`;
    `to_physical` / `from_physical` convert to and from the reported estimate
    (for example $b$ with $\\sum b_i^2 = 1$, seed 001 (3.10)).
    """

    @abc.abstractmethod
    def predict(self, theta: Params, v: Signal) -> Signal:
        """Noise-free output for the input samples `v`."""

    @abc.abstractmethod
    def to_physical(self, theta: Params) -> Float[Array, " n_physical"]:
        """The reported estimate."""

    @abc.abstractmethod
    def from_physical(self, physical: Float[Array, " n_physical"]) -> Params:
        """Free parameters reproducing a reported estimate."""

    @property
    @abc.abstractmethod
    def names(self) -> tuple[str, ...]:
        """Names of the entries of `to_physical(theta)`."""

    def is_valid(self, theta: Params) -> Bool[Array, ""]:
        """Whether `theta` is an admissible model (e.g. a stable linear block)."""
        del theta
        return jnp.array(True)
