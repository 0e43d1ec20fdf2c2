"""Cramér-Rao lower bound for output-error models under white Gaussian noise.

With $y = w(\\theta) + \\xi$, $\\xi \\sim N(0, \\sigma^2 I)$, the Fisher information
is $I(\\theta) = J^\\top J / \\sigma^2$ with $J = \\partial w / \\partial \\theta$ (here by
`jax.jacfwd` through the simulator). The free parameters $\\theta$ carry the
normalisation (G(0) = 1, or $\\sum b_i^2 = 1$ of seed 001 (3.10)), so $I$ is
invertible for an exciting input. The bound on reported parameters
$\\phi(\\theta)$ is $D I^{+} D^\\top$, $D = \\partial\\phi/\\partial\\theta$, which is the
bound for any $\\phi$ that the data identify (rows of $D$ in the row space of
$I$) even when $I$ is singular; entries that are not identified are NaN
(`fitting.covariance_from_information` with `singular="pseudo-inverse"`, the
routine the diagnosis's standard errors use with their own treatment).
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._types import Params, Signal
from ..fitting import covariance_from_information
from ._parametrisation import AbstractParametrisation


def output_jacobian(
    parametrisation: AbstractParametrisation, theta: Params, v: Signal
) -> Float[Array, "time n_params"]:
    """$\\partial w/\\partial\\theta$ by forward-mode differentiation of the simulator."""
    return jax.jacfwd(parametrisation.predict)(theta, v)


def fisher_information(
    parametrisation: AbstractParametrisation,
    theta: Float[ArrayLike, " n_params"],
    v: Float[ArrayLike, " time"],
    noise_std: float | Float[ArrayLike, ""],
) -> Float[Array, "n_params n_params"]:
    """$I(\\theta) = J^\\top J/\\sigma^2$ for white Gaussian output noise of std $\\sigma$."""
    return _fisher(
        parametrisation,
        jnp.asarray(theta, dtype=float),
        jnp.asarray(v, dtype=float),
        jnp.asarray(noise_std, dtype=float),
    )


@eqx.filter_jit
def _fisher(parametrisation, theta, v, noise_std):
    J = output_jacobian(parametrisation, theta, v)
    return J.T @ J / noise_std**2


def cramer_rao_bound(
    parametrisation: AbstractParametrisation,
    theta: Float[ArrayLike, " n_params"],
    v: Float[ArrayLike, " time"],
    noise_std: float | Float[ArrayLike, ""],
    *,
    physical: Callable[[Params], Array] | None = None,
) -> Float[Array, "n_physical n_physical"]:
    """Lower bound on the covariance of unbiased estimators of `physical(theta)`
    (default `parametrisation.to_physical`).

    Rows and columns of parameters the data do not identify are NaN.
    """
    theta = jnp.asarray(theta, dtype=float)
    phi = parametrisation.to_physical if physical is None else physical
    return _bound(
        parametrisation,
        theta,
        jnp.asarray(v, dtype=float),
        jnp.asarray(noise_std, dtype=float),
        phi,
    )


@eqx.filter_jit
def _bound(parametrisation, theta, v, noise_std, phi):
    info = _fisher(parametrisation, theta, v, noise_std)
    D = jax.jacfwd(phi)(theta)
    return covariance_from_information(info, jacobian=D, singular="pseudo-inverse")


def standard_errors(
    parametrisation: AbstractParametrisation,
    theta: Float[ArrayLike, " n_params"],
    v: Float[ArrayLike, " time"],
    noise_std: float | Float[ArrayLike, ""],
    *,
    physical: Callable[[Params], Array] | None = None,
) -> Float[Array, " n_physical"]:
    """Square roots of the diagonal of `cramer_rao_bound` (at an estimate, with an
    estimated $\\sigma$, the usual asymptotic standard errors)."""
    bound = cramer_rao_bound(parametrisation, theta, v, noise_std, physical=physical)
    return jnp.sqrt(jnp.diag(bound))
