"""One routine from an information matrix to covariances and standard errors.

For a least-squares fit $J^\\top J$ (over $\\sigma^2$: the Fisher information
under white Gaussian noise, $I = J^\\top J / \\sigma^2$), the covariance of
$\\phi(\\theta)$ is $D I^{-1} D^\\top$ with $D = \\partial\\phi/\\partial\\theta$
(Cramér-Rao; at an estimate with an estimated $\\sigma^2$, the Gauss-Newton
covariance). What differs between callers is a singular $I$, so it is an option:

- `singular="pseudo-inverse"` (the CRLB, `refinement.crlb`): $I$ scaled to unit
  diagonal, its eigenvalues below `1e-10` of the largest dropped, $D I^{+}
  D^\\top$; an entry whose gradient has a component (over `1e-6` relative) in the
  dropped directions is not identified: NaN. A bound on what the data identify,
  whatever the rest.
- `singular="infinite"` (the diagnosis's re-fits): a Cholesky factor of $I$ plus a
  ridge of `1e-12 (1 + I_ii)` over the `used` entries (rounding level of the
  diagonal: an exactly singular $I$ gives huge, finite errors along its null
  space); if the factorisation fails (an indefinite $I$, a pivot lost to
  rounding) every used entry is infinite: such a re-fit reads as "anything goes"
  in the decision, never as the finite errors of a sub-problem.

Entries outside `used` (padding slots) have zero variance in both.
"""

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, ArrayLike, Bool, Float


SINGULAR = ("pseudo-inverse", "infinite")


def _whitened(info, jacobian, used, singular):
    """`(A, ok)`: the covariance is `A^T A` on the entries `ok` (NaN or inf off)."""
    P = info.shape[0]
    D = jnp.eye(P, dtype=info.dtype) if jacobian is None else jacobian
    D = jnp.where(used[None, :], D, 0.0)
    if singular == "pseudo-inverse":
        # scale to unit diagonal first: the entries span many decades
        d = jnp.sqrt(jnp.diag(info))
        d = jnp.where(d > 0, d, 1.0)
        scaled = info / jnp.outer(d, d)
        Ds = D / d[None, :]
        eigval, eigvec = jnp.linalg.eigh(scaled)
        keep = eigval > 1e-10 * jnp.max(eigval)
        inv_val = jnp.where(keep, 1.0 / jnp.where(keep, eigval, 1.0), 0.0)
        DV = Ds @ eigvec
        A = (DV * jnp.sqrt(inv_val)[None, :]).T
        # phi_i is identified iff its gradient has no component in the null space
        leak = jnp.linalg.norm(DV * (~keep)[None, :], axis=1)
        ok = leak <= 1e-6 * jnp.maximum(jnp.linalg.norm(Ds, axis=1), 1e-300)
        return A, ok, jnp.nan
    reg = jnp.where(used, 1e-12 * (1.0 + jnp.diag(info)), 1.0)
    L = jnp.linalg.cholesky(info + jnp.diag(reg))
    A = jsl.solve_triangular(L, D.T, lower=True)
    ok = jnp.all(jnp.isfinite(A)) | ~jnp.any(used)
    return A, jnp.full(D.shape[0], ok), jnp.inf


def _check(singular):
    if singular not in SINGULAR:
        raise ValueError(f"singular must be one of {SINGULAR}; got {singular!r}")


def covariance_from_information(
    information: Float[ArrayLike, "P P"],
    *,
    singular: str,
    jacobian: Float[ArrayLike, "Q P"] | None = None,
    used: Bool[ArrayLike, " P"] | None = None,
) -> Float[Array, "Q Q"]:
    """$D I^{-1} D^\\top$ (`jacobian` $D$, default the identity) with `singular`'s
    treatment of unidentified directions (module doc)."""
    _check(singular)
    info = jnp.asarray(information)
    used = jnp.ones(info.shape[0], bool) if used is None else jnp.asarray(used)
    A, ok, bad = _whitened(info, jacobian, used, singular)
    cov = jnp.where(ok[:, None] & ok[None, :], A.T @ A, bad)
    if jacobian is None:  # padding entries: zero variance
        cov = jnp.where(used[:, None] & used[None, :], cov, 0.0)
    return cov


def standard_errors_from_information(
    information: Float[ArrayLike, "P P"],
    *,
    singular: str,
    variance: float | Float[ArrayLike, ""] = 1.0,
    jacobian: Float[ArrayLike, "Q P"] | None = None,
    used: Bool[ArrayLike, " P"] | None = None,
) -> Float[Array, " Q"]:
    """Square roots of the diagonal of `variance * covariance_from_information`
    (`variance`: e.g. the residual variance when `information` is $J^\\top J$)."""
    _check(singular)
    info = jnp.asarray(information)
    used = jnp.ones(info.shape[0], bool) if used is None else jnp.asarray(used)
    A, ok, bad = _whitened(info, jacobian, used, singular)
    var = jnp.sum(A**2, axis=0) * variance
    std = jnp.where(ok, jnp.sqrt(var), bad)
    return jnp.where(used, std, 0.0) if jacobian is None else std


standard_errors_jit = jax.jit(
    standard_errors_from_information, static_argnames=("singular",)
)
