"""Small dense linear algebra in plain `jax.numpy` (no LAPACK custom calls)."""

import jax.lax as lax
import jax.numpy as jnp
from jaxtyping import Array, Float


def fixed_order_sum(x: Float[Array, "*batch n"]) -> Float[Array, "*batch"]:
    """The sum of `x` along its last axis, in a pairwise order fixed by `n` alone.

    `jnp.sum` and `@` leave the order of their additions to XLA, which chooses it
    by the shape of the whole (vmapped) operation: the same row summed in batches
    of 16 and of 32 lanes, or on one device and on two, could differ in the last
    digits (up to 6e-14 in 256 samples, measured). Here every addition is
    elementwise (halves of the zero-padded axis added until one is left), and an
    elementwise addition rounds alike in every lane and every batch: a result
    depends on its own row, never on the rows beside it. Pairwise, it is also
    more accurate than a running sum (error $O(\\varepsilon \\log n)$).
    """
    n = x.shape[-1]
    width = 1 << max(n - 1, 0).bit_length()
    x = jnp.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, width - n)])
    while x.shape[-1] > 1:
        half = x.shape[-1] // 2
        x = x[..., :half] + x[..., half:]
    return x[..., 0]


def cholesky_solve(
    A: Float[Array, " n n"], b: Float[Array, " n *k"]
) -> Float[Array, " n *k"]:
    """Solve $A x = b$ for a symmetric positive-definite `A` by a Cholesky
    factorisation and two triangular sweeps.

    For the small systems of a damped Gauss-Newton step (n <= ~20). Written with
    `jax.numpy` arithmetic only: XLA's CPU LAPACK custom calls (`getrf`, `potrf`,
    `syevd`) were seen to hang when two devices ran them at once under jax 0.10,
    and under `vmap` this form is also faster for tiny n. A matrix that is not
    positive definite gives NaN, never a silent wrong answer.
    """
    n = A.shape[0]
    idx = jnp.arange(n)

    def column(j, L):  # columns >= j of L are still zero
        c = A[:, j] - fixed_order_sum(L * L[j][None])
        return L.at[:, j].set(jnp.where(idx >= j, c / jnp.sqrt(c[j]), 0.0))

    # Loops, not unrolled: the same arithmetic in a fraction of the compiled program.
    L = lax.fori_loop(0, n, column, jnp.zeros_like(A))
    x = b[:, None] if b.ndim == 1 else b

    def forward(i, y):  # rows >= i of y are still zero
        return y.at[i].set((x[i] - fixed_order_sum(L[i][None] * y.T)) / L[i, i])

    def backward(k, z):  # rows <= i of z are still zero
        i = n - 1 - k
        return z.at[i].set((y[i] - fixed_order_sum(L[:, i][None] * z.T)) / L[i, i])

    y = lax.fori_loop(0, n, forward, jnp.zeros_like(x))
    z = lax.fori_loop(0, n, backward, jnp.zeros_like(x))
    return z[:, 0] if b.ndim == 1 else z


def polymul(a: Float[Array, " n"], b: Float[Array, " m"]) -> Float[Array, " n+m-1"]:
    """The product of two polynomials' coefficient vectors (either order of
    powers): `jnp.convolve(a, b)`, written as `len(b)` shifted multiply-adds.

    Not `jnp.convolve`: under `vmap` JAX turns a convolution of batched operands
    into one grouped convolution, which XLA's CPU back end computes as a dense
    convolution with zero weights between the rows of the batch. A NaN or inf in
    one row's coefficients then turns every other row's product into NaN (0 x inf),
    and the rounding of each row changes with the batch size. Here each row is
    its own: the same numbers alone or in any batch.
    """
    n, m = a.shape[0], b.shape[0]
    out = jnp.zeros(n + m - 1, jnp.result_type(a, b))
    for j in range(m):  # m is static and small (a polynomial's degree + 1)
        out = out.at[j : j + n].add(a * b[j])
    return out


def charpoly_adjugate(A: Array) -> tuple[Array, Array]:
    """Faddeev-LeVerrier: monic char. poly (highest power first) and the matrices
    $M_k$ with $\\mathrm{adj}(zI - A) = \\sum_k M_k z^{n-k}$ (products only, so it
    differentiates cleanly; no LAPACK call). With them a state space $(A, B, C, D)$
    has the transfer function $(C\\,\\mathrm{adj}(zI - A) B + D \\det(zI - A)) /
    \\det(zI - A)$."""
    n = A.shape[0]
    eye = jnp.eye(n, dtype=A.dtype)

    def step(k, carry):  # k = 1..n
        M, c, Ms = carry
        M = A @ M + c[k - 1] * eye
        c = c.at[k].set(-jnp.trace(A @ M) / k.astype(A.dtype))
        return M, c, Ms.at[k - 1].set(M)

    c0 = jnp.zeros(n + 1, A.dtype).at[0].set(1.0)
    _, c, Ms = lax.fori_loop(
        1, n + 1, step, (jnp.zeros_like(A), c0, jnp.zeros((n, n, n), A.dtype))
    )
    return c, Ms
