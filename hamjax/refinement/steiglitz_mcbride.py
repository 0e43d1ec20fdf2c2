"""Steiglitz-McBride iterations for the seed-001 table model (input (5.1)).

Seed 001's closed form is least squares on the equation-error form (3.8a); with
output noise its error $\\eta = A z$ is coloured, so it is biased. Filtering the
regression by $1/\\hat A$ and iterating (Steiglitz and McBride, 1965) gives
estimates consistent for the output-error model, a safe start for `refine`.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._types import Signal
from ..models import DiscreteTransferFunction
from ._discrete import discrete_stable
from .normalisation import normalise_b


def _lags(x: Signal, n: int) -> Float[Array, "time n"]:
    """Columns $x(t-1), \\dots, x(t-n)$ (zero before the start)."""
    cols = [
        jnp.concatenate([jnp.zeros(i), x[: x.shape[0] - i]]) for i in range(1, n + 1)
    ]
    return jnp.stack(cols, axis=1)


def _one_over_a(a: Float[Array, " n"], x: Signal) -> Signal:
    """$x / A(q^{-1})$ from rest."""
    den = jnp.concatenate([jnp.ones(1), a])
    return DiscreteTransferFunction(jnp.ones(1), den).response(x)


def steiglitz_mcbride_table(
    v: Signal,
    y: Signal,
    levels: Float[Array, " 4"],
    a0: Float[Array, " n"],
    *,
    iterations: int = 20,
) -> Float[Array, " n_physical"]:
    """$(a, b, F(V_1..V_4))$ in the normalisation (3.10), by prefiltered least
    squares on $A y = \\sum_{i,j} b_i F(V_j)\\,\\mathbb 1[v(t-i) = V_j]$ (Eq. (3.7a))
    followed by the rank-1 factorisation (3.11)-(3.12).

    `a0` is the starting $A$ (e.g. the closed form's); an unstable filter is
    never used (the previous one is kept).
    """
    n = a0.shape[0]
    indicators = jnp.stack(
        [
            (jnp.abs(v - levels[j]) <= 1e-9 * jnp.abs(levels[j])).astype(float)
            for j in range(4)
        ],
        axis=1,
    )

    def fit(a_filter):
        yf = _one_over_a(a_filter, y)
        ef = jax.vmap(lambda e: _one_over_a(a_filter, e), in_axes=1, out_axes=1)(
            indicators
        )
        X = jnp.concatenate(
            [-_lags(yf, n)] + [_lags(ef[:, j], n) for j in range(4)], axis=1
        )
        theta, *_ = jnp.linalg.lstsq(X, yf)
        return theta[:n], theta[n:].reshape(4, n).T  # C[i, j] = b_i F(V_j)

    def step(a_filter, _):
        a, C = fit(a_filter)
        a_next = jnp.where(discrete_stable(a), a, a_filter)
        return a_next, None

    a_start = jnp.where(discrete_stable(a0), a0, jnp.zeros(n))
    a_last, _ = jax.lax.scan(step, a_start, None, length=iterations)
    a, C = fit(a_last)
    # Eq. (3.11)-(3.12): C = b F^T is rank 1 (up to noise).
    U, s, Vt = jnp.linalg.svd(C, full_matrices=False)
    b, g = normalise_b(U[:, 0])
    f = s[0] * Vt[0] * g
    return jnp.concatenate([a, b, f])
