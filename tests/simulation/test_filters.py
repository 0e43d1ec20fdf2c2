"""The one linear filter (`hamjax._filters`): companion form, matrix
exponential, zero-order hold and direct form II transposed against scipy, and each
host (NumPy) twin against its JAX path."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from scipy import signal

from hamjax._filters import (
    companion,
    df2t_step,
    expm_taylor,
    filter_scan,
    lfilter_numpy,
    state_space_numpy,
    zoh,
    zoh_tf,
)
from hamjax._linalg import charpoly_adjugate


# Rounding: a few hundred float64 operations per entry, each within 2^-53; 1e-12
# relative leaves three orders of magnitude for their accumulation.
RTOL = 1e-12

TFS = (
    ([2.0, 1.0], [1.0, 3.0, 2.0]),
    ([1.0, 2.0, 1.0], [2.0, 3.0, 2.0]),  # biproper, not monic
    ([0.5], [1.0, 0.4, 2.0, 0.3]),  # numerator shorter by two
    ([3.0], [2.0]),  # a static gain
)


@pytest.mark.parametrize("num, den", TFS)
@pytest.mark.parametrize("xp", [jnp, np])
def test_companion_equals_tf2ss(num, den, xp):
    mine = companion(num, den, xp=xp)
    if len(den) == 1:  # a static gain: no state (scipy pads one zero state)
        assert [m.shape for m in mine] == [(0, 0), (0, 1), (1, 0), (1, 1)]
        assert float(mine[3][0, 0]) == num[0] / den[0]
        return
    for m, ref in zip(mine, signal.tf2ss(num, den), strict=True):
        assert m.shape == ref.shape
        np.testing.assert_allclose(np.asarray(m), ref, rtol=RTOL, atol=1e-15)


def test_expm_and_its_tangent_equal_scipy():
    rng = np.random.default_rng([17, 0])
    for scale in (1e-3, 1.0, 10.0):  # |M| dt from tiny to far beyond any sampling
        M = scale * rng.normal(size=(5, 5))
        T = rng.normal(size=(5, 5))
        ref, dref = scipy.linalg.expm_frechet(M, T)
        E, dE = jax.jvp(expm_taylor, (jnp.asarray(M),), (jnp.asarray(T),))
        # 12 squarings multiply the rounding of the series by up to 2^12 relative
        # to |e^M|: 1e-12 * 2^12 bounds it for the tangent as for the value.
        tol = RTOL * 2.0**12
        np.testing.assert_allclose(E, ref, rtol=0, atol=tol * np.abs(ref).max())
        np.testing.assert_allclose(dE, dref, rtol=0, atol=tol * np.abs(dref).max())


@pytest.mark.parametrize("num, den", TFS[:3])
def test_zoh_equals_cont2discrete_and_its_numpy_twin(num, den):
    dt = 0.07
    ref = signal.cont2discrete(signal.tf2ss(num, den), dt, method="zoh")[:4]
    for xp in (jnp, np):
        for mine, r in zip(zoh_tf(num, den, dt, xp=xp), ref, strict=True):
            np.testing.assert_allclose(np.asarray(mine), r, rtol=RTOL, atol=1e-14)
    A, B, _, _ = companion(num, den, xp=np)
    twin = zoh(A, B, dt, xp=np)
    for mine, ref in zip(zoh(A, B, dt), twin, strict=True):
        np.testing.assert_allclose(mine, ref, rtol=RTOL, atol=1e-14)
    # the diagnosis's exponential: 12 squarings of the series' rounding
    for mine, ref in zip(zoh(A, B, dt, expm=expm_taylor), twin, strict=True):
        np.testing.assert_allclose(mine, ref, rtol=RTOL * 2.0**12, atol=1e-14)


def _filter(rng, order):
    a = np.poly(rng.uniform(-0.9, 0.9, size=order))  # stable, monic
    return rng.normal(size=order + 1), a


@pytest.mark.parametrize("order", [1, 3, 5])
def test_filter_scan_equals_lfilter_and_chains_over_blocks(order):
    rng = np.random.default_rng([17, order])
    b, a = _filter(rng, order)
    u = rng.normal(size=300)
    ref = signal.lfilter(b, a, u)
    z0 = jnp.zeros(order)
    _, y = filter_scan(jnp.asarray(b), jnp.asarray(a), jnp.asarray(u), z0)
    np.testing.assert_allclose(y, ref, rtol=0, atol=RTOL * np.abs(ref).max())
    z, y1 = filter_scan(jnp.asarray(b), jnp.asarray(a), jnp.asarray(u[:123]), z0)
    _, y2 = filter_scan(jnp.asarray(b), jnp.asarray(a), jnp.asarray(u[123:]), z)
    np.testing.assert_array_equal(np.concatenate([y1, y2]), y)


def test_batched_step_equals_each_column():
    rng = np.random.default_rng([17, 9])
    b, a = (jnp.asarray(x) for x in _filter(rng, 3))
    U = jnp.asarray(rng.normal(size=(200, 4)))  # time-major batch
    _, Y = filter_scan(b, a, U, jnp.zeros((3, 4)))
    for j in range(4):  # the same operations; XLA may fuse them differently (ulps)
        _, y = filter_scan(b, a, U[:, j], jnp.zeros(3))
        np.testing.assert_allclose(Y[:, j], y, rtol=0, atol=RTOL * np.abs(y).max())
    # a static gain keeps its (zero) state and multiplies
    z, y = df2t_step(b[:1], a[:1], jnp.zeros((1, 4)), U[0])
    np.testing.assert_array_equal(y, b[0] * U[0])
    np.testing.assert_array_equal(z, jnp.zeros((1, 4)))


@pytest.mark.parametrize("order", [1, 4])
def test_lfilter_numpy_equals_scipy_and_the_jax_filter(order):
    rng = np.random.default_rng([17, 100 + order])
    b, a = _filter(rng, order)
    U = rng.normal(size=(3, 500))
    ref = signal.lfilter(b, a, U, axis=1)
    atol = RTOL * np.abs(ref).max()
    np.testing.assert_allclose(lfilter_numpy(b, a, U), ref, rtol=0, atol=atol)
    _, y = filter_scan(
        jnp.asarray(b), jnp.asarray(a), jnp.asarray(U[0]), jnp.zeros(order)
    )
    for one in (lfilter_numpy(b, a, U[0]), np.asarray(y)):
        np.testing.assert_allclose(one, ref[0], rtol=0, atol=atol)


def test_charpoly_adjugate_equals_poly_and_adjugate():
    rng = np.random.default_rng([17, 200])
    A = rng.normal(size=(4, 4))
    c, Ms = charpoly_adjugate(jnp.asarray(A))
    np.testing.assert_allclose(c, np.poly(A), rtol=RTOL, atol=1e-12)
    z = 1.7  # adj(zI - A) = det(zI - A) (zI - A)^-1
    adj = np.einsum("k,kij->ij", z ** np.arange(3, -1, -1.0), np.asarray(Ms))
    R = z * np.eye(4) - A
    np.testing.assert_allclose(adj, np.linalg.det(R) * np.linalg.inv(R), rtol=1e-10)


@pytest.mark.parametrize(
    "num, den, dt",
    [
        *((n, d, 0.05) for n, d in TFS),
        ([1.0], [1.0, 3.0, 3.0, 1.0], 1e-3),  # a triple pole at z = 0.999
        ([1.0], [1.0, 0.0], 0.01),  # an integrator
        ([3.0], [1.0], 0.1),  # a static gain: no state
    ],
)
def test_state_space_numpy_equals_the_recursion_and_dlsim(num, den, dt):
    # Against scipy.signal.dlsim (its own step-by-step loop) on records that
    # end inside a block and on several inputs at once. The triple pole is where
    # a transfer-function form loses ~1e-7 (its coefficients' sensitivity
    # 1/(1 - z)^3); the blocks keep the recursion's rounding: a sum of at most
    # STATE_BLOCK products per sample and a state carried as often, 1e-12
    # relative to the output's largest value.
    A, B, C, D = zoh_tf(np.asarray(num), np.asarray(den), dt, xp=np)
    u = np.random.default_rng(7).normal(size=(3, 1000))
    u[1] = np.repeat(u[1, :50], 20)  # a staircase
    got = state_space_numpy(A, B, C, D, u)
    for k in range(3):
        if A.shape[0]:
            _, ref, _ = signal.dlsim((A, B, C, D, 1.0), u[k])
            ref = ref[:, 0]
        else:
            ref = float(D[0, 0]) * u[k]
        scale = np.max(np.abs(ref))
        np.testing.assert_allclose(got[k], ref, rtol=0, atol=1e-12 * scale)
        one = state_space_numpy(A, B, C, D, u[k, :777])  # 12 blocks and a part
        np.testing.assert_allclose(one, ref[:777], rtol=0, atol=1e-12 * scale)
        short = state_space_numpy(A, B, C, D, u[k, :40])  # less than one block
        np.testing.assert_allclose(short, ref[:40], rtol=0, atol=1e-12 * scale)
    # two batch axes: each record as alone
    grid = state_space_numpy(A, B, C, D, u[None, :, :300].repeat(2, axis=0))
    assert grid.shape == (2, 3, 300)
    peak = np.max(np.abs(got))
    np.testing.assert_allclose(grid[1], got[:, :300], rtol=0, atol=1e-12 * peak)
