"""The normalisation (3.10) of seed 001 and a local chart of the unit sphere.

Giri, Rochdi, Chaoui, *Recursive identification of systems with hard input
nonlinearities of known structure*, Section III.B.
"""

import jax.numpy as jnp
from jaxtyping import Array, Float


def sign_rule(b: Float[Array, " n"]) -> Float[Array, ""]:
    """$\\mathrm{sign}\\,\\rho(b)$ of (3.10): the sign of the first entry of largest
    magnitude (+1 for $b = 0$)."""
    rho = b[jnp.argmax(jnp.abs(b))]
    return jnp.where(rho < 0, -1.0, 1.0)


def tangent_basis(b_ref: Float[Array, " n"]) -> Float[Array, "n n_minus_1"]:
    """Orthonormal basis of the complement of the unit vector `b_ref` (Householder)."""
    n = b_ref.shape[0]
    e1 = jnp.zeros(n).at[0].set(1.0)
    s = jnp.where(b_ref[0] < 0, -1.0, 1.0)
    w = b_ref + s * e1
    H = jnp.eye(n) - 2.0 * jnp.outer(w, w) / jnp.dot(w, w)
    return H[:, 1:]


def sphere_point(
    b_ref: Float[Array, " n"], delta: Float[Array, " n_minus_1"]
) -> Float[Array, " n"]:
    """$(b_{ref} + P\\delta)/\\|b_{ref} + P\\delta\\|$: a chart of $\\sum b_i^2 = 1$ at
    $b_{ref}$, so the free parameters are identifiable (Eq. (3.10))."""
    x = b_ref + tangent_basis(b_ref) @ delta
    return x / jnp.linalg.norm(x)


def sphere_coordinates(
    b_ref: Float[Array, " n"], b: Float[Array, " n"]
) -> Float[Array, " n_minus_1"]:
    """Inverse of `sphere_point` (valid on the hemisphere $b \\cdot b_{ref} > 0$)."""
    return tangent_basis(b_ref).T @ b / jnp.dot(b_ref, b)


def normalise_b(b: Float[Array, " n"]) -> tuple[Float[Array, " n"], Float[Array, ""]]:
    """`(b / g, g)` with $g = \\pm\\|b\\|$ chosen so that `b / g` satisfies (3.10);
    the nonlinearity's output scale is multiplied by `g`."""
    g = jnp.linalg.norm(b) * sign_rule(b)
    return b / g, g
