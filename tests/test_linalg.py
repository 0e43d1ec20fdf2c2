"""`hamjax._linalg`: `cholesky_solve` against NumPy's LAPACK solve, `polymul`
against `np.convolve`, `fixed_order_sum` against `math.fsum` and across batch
widths."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import needs_isa_cap

from hamjax._linalg import cholesky_solve, fixed_order_sum, polymul


def _spd(rng, n, cond=1e3):
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return Q @ np.diag(np.geomspace(1.0, 1.0 / cond, n)) @ Q.T


@pytest.mark.parametrize("n", [1, 2, 5, 13])
def test_matches_numpy_solve(n):
    rng = np.random.default_rng(n)
    A, b, B = _spd(rng, n), rng.normal(size=n), rng.normal(size=(n, 3))
    # forward error <= cond(A) * eps * small factor: 1e3 * 2.2e-16 * 100
    np.testing.assert_allclose(
        cholesky_solve(jnp.asarray(A), jnp.asarray(b)),
        np.linalg.solve(A, b),
        rtol=0,
        atol=3e-11 * np.abs(np.linalg.solve(A, b)).max(),
    )
    np.testing.assert_allclose(
        cholesky_solve(jnp.asarray(A), jnp.asarray(B)),
        np.linalg.solve(A, B),
        rtol=0,
        atol=3e-11 * np.abs(np.linalg.solve(A, B)).max(),
    )


def test_vmap_and_not_positive_definite():
    rng = np.random.default_rng(0)
    As = np.stack([_spd(rng, 4) for _ in range(6)])
    bs = rng.normal(size=(6, 4))
    out = jax.vmap(cholesky_solve)(jnp.asarray(As), jnp.asarray(bs))
    np.testing.assert_allclose(
        out, np.linalg.solve(As, bs[..., None])[..., 0], rtol=1e-9
    )
    # an indefinite matrix must not return a plausible-looking answer
    x = cholesky_solve(-jnp.asarray(As[0]), jnp.asarray(bs[0]))
    assert np.all(np.isnan(np.asarray(x)))


@pytest.mark.parametrize("n, m", [(1, 1), (3, 2), (5, 5), (2, 7)])
def test_polymul_matches_numpy_convolve(n, m):
    rng = np.random.default_rng(10 * n + m)
    a, b = rng.normal(size=n), rng.normal(size=m)
    # each output is a sum of at most min(n, m) products: rounding only
    np.testing.assert_allclose(
        polymul(jnp.asarray(a), jnp.asarray(b)),
        np.convolve(a, b),
        rtol=1e-14,
        atol=1e-15,
    )


def test_polymul_rows_of_a_batch_stay_apart():
    # Under vmap `jnp.convolve` becomes one grouped convolution, computed on CPU as
    # a dense one with zero weights between rows: an inf in one row made every
    # other row NaN (0 x inf), which stalled the diagnosis's fits of whole cases
    # batched beside a diverging row. Each row must equal its own product,
    # bit for bit, whatever its batch-mates hold.
    rng = np.random.default_rng(1)
    A, B = rng.normal(size=(4, 5)), rng.normal(size=(4, 2))
    A[2], B[3] = np.inf, np.nan
    out = np.asarray(jax.vmap(polymul)(jnp.asarray(A), jnp.asarray(B)))
    for k in (0, 1):
        np.testing.assert_array_equal(
            out[k], np.asarray(polymul(jnp.asarray(A[k]), jnp.asarray(B[k])))
        )
    assert np.isfinite(out[:2]).all()


@pytest.mark.parametrize("n", [1, 2, 7, 256, 1000])
def test_fixed_order_sum_matches_math_fsum(n):
    """Against the exactly rounded sum (`math.fsum`): a pairwise sum's error is at
    most about log2(n) eps sum|x| (Higham, *Accuracy and Stability of Numerical
    Algorithms*, 2002, sec. 4.2); 2 log2(2n) eps sum|x| allows for the padding."""
    import math

    x = np.random.default_rng(n).normal(size=(3, n))
    got = np.asarray(fixed_order_sum(jnp.asarray(x)))
    for row, s in zip(x, got, strict=True):
        bound = 2 * math.log2(2 * n) * np.finfo(float).eps * np.abs(row).sum()
        assert abs(s - math.fsum(row)) <= bound


@needs_isa_cap
def test_fixed_order_sum_of_a_row_does_not_depend_on_its_batch():
    """The property it exists for: a row's sum bitwise the same whatever rows share
    its vmapped batch (widths 1-32, as other device counts and chunk sizes cut a
    call). `x @ x` over the same rows differed by up to 6e-14 between widths."""
    rng = np.random.default_rng(2)
    r, J = rng.normal(size=(32, 256)), rng.normal(size=(32, 5, 256))
    sq = jax.jit(jax.vmap(lambda r: fixed_order_sum(r * r)))
    gram = jax.jit(jax.vmap(lambda J: fixed_order_sum(J[:, None] * J[None])))
    ref_sq, ref_gram = np.asarray(sq(r)), np.asarray(gram(J))
    for width in (1, 3, 5, 8, 16, 17):
        for s in range(0, 32, width):
            at = slice(s, s + width)
            np.testing.assert_array_equal(np.asarray(sq(r[at])), ref_sq[at])
            np.testing.assert_array_equal(np.asarray(gram(J[at])), ref_gram[at])
