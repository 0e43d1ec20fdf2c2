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

One routine for two array libraries: JAX arrays in (traced too: `refinement.crlb`
runs it under `jit`), JAX out; NumPy arrays in, NumPy out, on the host with no
compilation (the diagnosis calls it once per fitted row; a jitted call compiled
in about a second, several percent of a 60-case `hamjax diagnose`).
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float


SINGULAR = ("pseudo-inverse", "infinite")


def _namespace(*xs):
    """NumPy for NumPy inputs (or Python numbers), else `jax.numpy`."""
    host = all(isinstance(x, np.ndarray | float | int | np.generic | None) for x in xs)
    return np if host else jnp


def _cholesky(xp, A):
    """The lower Cholesky factor; NaN if `A` is not positive definite (JAX's
    behaviour, which NumPy signals by raising)."""
    if xp is jnp:
        return jnp.linalg.cholesky(A)
    try:
        return np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return np.full_like(A, np.nan)


def _whitened(xp, info, jacobian, used, singular):
    """`(A, ok, bad)`: the covariance is `A^T A` on the entries `ok`, `bad` (NaN or
    inf) off them."""
    P = info.shape[0]
    D = xp.eye(P, dtype=info.dtype) if jacobian is None else jacobian
    D = xp.where(used[None, :], D, 0.0)
    if singular == "pseudo-inverse":
        # scale to unit diagonal first: the entries span many decades
        d = xp.sqrt(xp.diag(info))
        d = xp.where(d > 0, d, 1.0)
        scaled = info / xp.outer(d, d)
        Ds = D / d[None, :]
        eigval, eigvec = xp.linalg.eigh(scaled)
        keep = eigval > 1e-10 * xp.max(eigval)
        inv_val = xp.where(keep, 1.0 / xp.where(keep, eigval, 1.0), 0.0)
        DV = Ds @ eigvec
        A = (DV * xp.sqrt(inv_val)[None, :]).T
        # phi_i is identified iff its gradient has no component in the null space
        leak = xp.linalg.norm(DV * (~keep)[None, :], axis=1)
        ok = leak <= 1e-6 * xp.maximum(xp.linalg.norm(Ds, axis=1), 1e-300)
        return A, ok, xp.nan
    reg = xp.where(used, 1e-12 * (1.0 + xp.diag(info)), 1.0)
    L = _cholesky(xp, info + xp.diag(reg))
    A = xp.linalg.inv(L) @ D.T  # scipy's solve_triangular: ~80x slower here
    ok = xp.all(xp.isfinite(A)) | ~xp.any(used)
    return A, xp.full(D.shape[0], ok), xp.inf


def _prepare(information, jacobian, used, singular):
    if singular not in SINGULAR:
        raise ValueError(f"singular must be one of {SINGULAR}; got {singular!r}")
    xp = _namespace(information, jacobian, used)
    info = xp.asarray(information, dtype=float)
    used = xp.ones(info.shape[0], bool) if used is None else xp.asarray(used, bool)
    return xp, _whitened(xp, info, jacobian, used, singular), used


def covariance_from_information(
    information: Float[ArrayLike, "P P"],
    *,
    singular: str,
    jacobian: Float[ArrayLike, "Q P"] | None = None,
    used: Bool[ArrayLike, " P"] | None = None,
) -> Float[Array, "Q Q"]:
    """$D I^{-1} D^\\top$ (`jacobian` $D$, default the identity) with `singular`'s
    treatment of unidentified directions (module doc)."""
    xp, (A, ok, bad), used = _prepare(information, jacobian, used, singular)
    cov = xp.where(ok[:, None] & ok[None, :], A.T @ A, bad)
    if jacobian is None:  # padding entries: zero variance
        cov = xp.where(used[:, None] & used[None, :], cov, 0.0)
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
    xp, (A, ok, bad), used = _prepare(information, jacobian, used, singular)
    var = xp.sum(A**2, axis=0) * variance
    std = xp.where(ok, xp.sqrt(var), bad)
    return xp.where(used, std, 0.0) if jacobian is None else std
