"""`simulate`, `linear_response` and `simulate_diffrax` against scipy.signal and
each other; jit, vmap and grad; the seed-000 normalisation."""

import equinox as eqx
import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from helpers import random_stable_poly, reference_backlash, reference_zoh
from hypothesis import given, settings
from scipy import signal

import hamjax as hj


SEED001 = dict(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0)


def _np_pl(v, k1, k2, d1, d2, l1, l2):
    return np.where(
        v > d1, k1 * (v - d1) + l1, np.where(v < d2, k2 * (v - d2) + l2, 0.0)
    )


@eqx.filter_jit
def _simulate(plant, v, dt=None):
    return hj.simulate(plant, v, dt=dt)


# --- discrete --------------------------------------------------------------------


@given(
    order=st.integers(1, 4),
    roots=hnp.arrays(np.float64, 4, elements=st.floats(-1, 1)),
    b=hnp.arrays(np.float64, 5, elements=st.floats(-2, 2)),
    delay=st.booleans(),
)
@settings(max_examples=25, deadline=None, derandomize=True)
def test_discrete_simulation_equals_lfilter(order, roots, b, delay):
    a = random_stable_poly(roots[:order])
    b = b[: order + 1].copy()
    if delay:
        b[0] = 0.0
    F = hj.PiecewiseLinear(**SEED001)
    _, v = hj.random_staircase(jr.key(order), n_samples=300, hold=3, low=-7.0, high=7.0)
    w = _simulate(hj.Hammerstein(F, hj.DiscreteTransferFunction(b, a)), v)
    u = _np_pl(np.asarray(v), **SEED001)
    ref = signal.lfilter(b, a, u)
    np.testing.assert_allclose(w, ref, rtol=0, atol=_rounding_bound(b, a, u, ref))


def _rounding_bound(b, a, u, y) -> float:
    """What two evaluations of the recursion a(q) y = b(q) u may differ by in
    float64: each step rounds its sum by about eps (sum |a_j y| + sum |b_j u|),
    and that error runs on through 1/a(q), whose gain is at most the l1 norm of
    its impulse response; times 8 for both evaluations and the order of their
    sums. A 4-fold pole at -0.95 (hypothesis drew it) has gain 1/0.05^4 = 1.6e5:
    there 1e-12 of the output's size was too tight; elsewhere this is smaller."""
    eps = np.finfo(float).eps
    gain = np.abs(signal.lfilter([1.0], a, np.r_[1.0, np.zeros(y.shape[0] - 1)]))
    per_step = np.abs(a).sum() * np.abs(y).max() + np.abs(b).sum() * np.abs(u).max()
    return max(1e-12 * max(1.0, np.abs(y).max()), 8 * eps * gain.sum() * per_step)


def test_seed001_plant_on_the_pe_input():
    # Section V.C: A = 1 - 1.5 q^-1 + 0.56 q^-2, B = q^-1 - 2 q^-2, input (5.1).
    b, a = np.array([0.0, 1.0, -2.0]), np.array([1.0, -1.5, 0.56])
    plant = hj.Hammerstein(
        hj.PiecewiseLinear(**SEED001), hj.DiscreteTransferFunction(b, a)
    )
    _, v = hj.pe_impulse_sequence(
        jnp.array([-6.0, -3.0, 3.0, 6.0]), order=2, periods=30
    )
    w = hj.simulate(plant, v)
    np.testing.assert_allclose(
        w, signal.lfilter(b, a, _np_pl(np.asarray(v), **SEED001)), atol=1e-11
    )


def test_simulate_with_backlash_equals_reference_chain(getkey):
    bl = hj.Backlash.from_width(0.4, u0=0.0)
    b, a = np.array([0.0, 0.3]), np.array([1.0, -0.7])
    v = 0.5 * jnp.cumsum(jr.normal(getkey(), (200,)))
    # Any draw: the walk is ~7 (its end point's sigma), at most ~40; G has gain 1
    # and a pole 0.7, so rounding is ~1e-14 and atol 1e-11 leaves a margin of 1000.
    w = _simulate(hj.Hammerstein(bl, hj.DiscreteTransferFunction(b, a)), v)
    u = reference_backlash(np.asarray(v), lambda x: x - 0.2, lambda x: x + 0.2, 0.0)
    np.testing.assert_allclose(w, signal.lfilter(b, a, u), atol=1e-11)


# --- continuous --------------------------------------------------------------------


CT_PLANTS = [
    ([1.0], [1.0, 1.0]),  # 1/(s + 1)
    ([1.0, -10.0], [1.0, 2.0, 1.0]),  # seed 000 Fig. 6
    ([1.0], [0.25, 1.0, 1.0]),  # contract_check: 1/(0.5 s + 1)^2
    ([0.5, 0.2, 1.0], [1.0, 1.2, 2.0, 0.8]),  # third order, poles with +-j
    ([2.0, 0.0, 1.0, 3.0, 1.0], [1.0, 3.0, 4.0, 2.5, 0.6]),  # biproper, fourth order
]


@pytest.mark.parametrize("num,den", CT_PLANTS)
def test_zoh_simulation_equals_scipy(num, den):
    dt = 0.05
    _, v = hj.random_staircase(jr.key(3), n_samples=400, hold=7, low=-2.0, high=2.0)
    F = hj.DeadZone(lower=-0.3, upper=0.5)
    w = _simulate(hj.Hammerstein(F, hj.ContinuousTransferFunction(num, den)), v, dt)
    ref = reference_zoh(num, den, np.asarray(F(v)), dt)
    np.testing.assert_allclose(w, ref, rtol=0, atol=1e-10)


@pytest.mark.slow  # diffrax compilation
@pytest.mark.parametrize("num,den", [CT_PLANTS[1]])
def test_diffrax_hold_equals_zoh(num, den):
    dt = 0.1
    bl, _ = _borders()
    plant = hj.Hammerstein(bl, hj.ContinuousTransferFunction(num, den))
    _, v0 = hj.initialisation_step(jnp.array([-1.5, 0.0, 1.5]), duration=0.5, dt=dt)
    _, v1 = hj.nbbi_staircase(jnp.array([-1.5, -0.5, 0.5, 1.5]), hold=3.0, dt=dt)
    v = jnp.concatenate([v0, v1])
    t = jnp.arange(v.shape[0]) * dt
    w_zoh = _simulate(plant, v, dt)
    w_ode = eqx.filter_jit(hj.simulate_diffrax)(plant, t, v)
    np.testing.assert_allclose(w_ode, w_zoh, rtol=0, atol=1e-6)


@pytest.mark.slow  # diffrax compilation
def test_diffrax_linear_interpolation_equals_lsim():
    # scipy's lsim interpolates the input linearly between samples (first-order hold).
    num, den = [1.0, 0.5], [1.0, 1.2, 2.0, 0.8]
    t = jnp.linspace(0.0, 10.0, 201)
    u = jnp.sin(1.3 * t) + 0.5 * jnp.cos(3.1 * t)
    y = hj.simulate_diffrax(
        hj.ContinuousTransferFunction(num, den), t, u, interpolation="linear"
    )
    _, ref, _ = signal.lsim((num, den), np.asarray(u), np.asarray(t))
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-6)


def test_discretised_block_equals_continuous_block():
    G = hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0])
    v = jnp.asarray(np.repeat(np.linspace(-1, 1, 9), 20))
    F = hj.Saturation(lower=-0.5, upper=0.8)
    w_ct = hj.simulate(hj.Hammerstein(F, G), v, dt=0.02)
    w_dt = hj.simulate(hj.Hammerstein(F, G.discretise(0.02)), v)
    np.testing.assert_allclose(w_ct, w_dt, atol=1e-14)
    # The settled step response is the static gain -10.
    np.testing.assert_allclose(
        hj.linear_response(G, jnp.ones(2000), dt=0.02)[-1], -10.0, rtol=1e-9
    )


# --- normalisation --------------------------------------------------------------------


def _borders():
    grid = jnp.linspace(-3.0, 3.0, 31)
    shape = grid + 0.05 * grid**3
    return hj.Backlash.from_table(grid, shape - 0.3, shape + 0.3), grid


@pytest.mark.parametrize(
    "make_plant",
    [
        lambda: hj.Hammerstein(
            _borders()[0], hj.ContinuousTransferFunction([1.0, -10.0], [1.0, 2.0, 1.0])
        ),
        lambda: hj.Hammerstein(
            _borders()[0], hj.ContinuousTransferFunction([3.0], [1.0, 2.0])
        ),
        lambda: hj.Hammerstein(
            hj.PiecewiseLinear(**SEED001),
            hj.DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56]),
        ),
    ],
    ids=["seed000-fig6-backlash-k<0", "backlash-k>0", "seed001-k<0"],
)
def test_normalise_static_gain_preserves_behaviour(make_plant, getkey):
    plant = make_plant()
    normalised = hj.normalise_static_gain(plant)
    # deterministic: G(0) / G(0), one or two roundings
    np.testing.assert_allclose(normalised.linear.static_gain(), 1.0, rtol=1e-14)
    # Any draw: |v| <= 2.5 by construction, so the outputs are bounded (|k| <= 10)
    # and 1e-12 is a fixed multiple of their rounding whatever the seed.
    v = 1.5 * jnp.sin(jnp.cumsum(jr.uniform(getkey(), (300,), maxval=0.2)))
    v = jnp.concatenate([v, jnp.repeat(jnp.array([-2.0, 1.0, 2.5, -0.4, 0.3]), 30)])
    dt = 0.05
    np.testing.assert_allclose(
        _simulate(normalised, v, dt), _simulate(plant, v, dt), rtol=1e-12, atol=1e-12
    )


def test_normalise_zero_gain_raises():
    plant = hj.Hammerstein(
        hj.Identity(), hj.ContinuousTransferFunction([1.0, 0.0], [1.0, 1.0])
    )
    with pytest.raises(ValueError, match="static gain G\\(0\\) is 0"):
        hj.normalise_static_gain(plant)


# --- transformations -----------------------------------------------------------------


def test_jit_equals_eager(getkey):
    plant = hj.Hammerstein(
        hj.Backlash.from_width(0.3),
        hj.ContinuousTransferFunction([1.0], [1.0, 1.4, 1.0]),
    )
    v = jnp.cumsum(jr.normal(getkey(), (150,))) * 0.2
    ref = hj.simulate(plant, v, dt=0.1)
    # The same operations, fused or not: a few ulp of the states. The outputs scale
    # with the random walk (and cross zero), so the absolute part is 16 eps of the
    # output's peak rather than a fixed 1e-14.
    np.testing.assert_allclose(
        jax.jit(lambda v: hj.simulate(plant, v, dt=0.1))(v),
        ref,
        rtol=1e-14,
        atol=16 * np.finfo(float).eps * float(jnp.max(jnp.abs(ref))),
    )


def test_vmap_equals_loop(getkey):
    F = hj.PiecewiseLinear(**SEED001)
    vs = jr.uniform(getkey(), (5, 120), minval=-7, maxval=7)
    a1 = jnp.array([-0.5, -0.9, 0.2, 0.7, -0.1])

    def run(a1, v):
        return hj.simulate(
            hj.Hammerstein(
                F,
                hj.DiscreteTransferFunction(
                    jnp.array([0.0, 1.0]), jnp.stack([1.0, a1])
                ),
            ),
            v,
        )

    batched = jax.vmap(run)(a1, vs)
    loop = np.stack([run(a, v) for a, v in zip(a1, vs, strict=True)])
    # Same operations, batched or not: a few ulp of the states, whose size (up to
    # ~10 / (1 - 0.9) = 100 here) depends on the draw. Outputs cross zero, so the
    # absolute part is 16 eps of the peak (3.6e-14 at 10), not a fixed 1e-14.
    atol = 16 * np.finfo(float).eps * np.abs(loop).max()
    np.testing.assert_allclose(batched, loop, rtol=1e-14, atol=atol)
    same_plant = jax.vmap(run, in_axes=(None, 0))(a1[0], vs)
    loop = np.stack([run(a1[0], v) for v in vs])
    atol = 16 * np.finfo(float).eps * np.abs(loop).max()
    np.testing.assert_allclose(same_plant, loop, rtol=1e-14, atol=atol)


def _fd(f, x, h=1e-6):
    x = jnp.asarray(x, float)
    return np.array(
        [(f(x.at[i].add(h)) - f(x.at[i].add(-h))) / (2 * h) for i in range(x.shape[0])]
    )


def _check_grad(loss, x, rtol=1e-6):
    loss = jax.jit(loss)
    g = jax.grad(loss)(jnp.asarray(x, float))
    np.testing.assert_allclose(
        g, _fd(loss, x), rtol=rtol, atol=1e-8 * max(1.0, np.abs(g).max())
    )
    assert np.all(np.abs(g) > 0)


V_GRAD = jnp.asarray(np.repeat([0.5, 2.0, -1.0, 3.0, -3.5, 1.2], 15))


def test_grad_wrt_discrete_a_and_b():
    F = hj.PiecewiseLinear(**SEED001)

    def loss(theta):
        G = hj.DiscreteTransferFunction(
            jnp.concatenate([jnp.zeros(1), theta[2:]]),
            jnp.concatenate([jnp.ones(1), theta[:2]]),
        )
        return jnp.sum(hj.simulate(hj.Hammerstein(F, G), V_GRAD) ** 2) / V_GRAD.shape[0]

    _check_grad(loss, [-1.5, 0.56, 1.0, -2.0])


def test_grad_wrt_nonlinearity_parameters():
    G = hj.DiscreteTransferFunction(
        jnp.array([0.0, 1.0, -2.0]), jnp.array([1.0, -1.5, 0.56])
    )

    def loss(p):
        F = hj.PiecewiseLinear(k1=p[0], k2=p[1], d1=p[2], d2=p[3], l1=p[4], l2=p[5])
        return jnp.mean(hj.simulate(hj.Hammerstein(F, G), V_GRAD) ** 2)

    _check_grad(loss, [1.0, 2.0, 1.0, -2.0, 1.0, -2.0])


def test_grad_wrt_continuous_num_den():
    F = hj.DeadZone.symmetric(0.2)

    def loss(p):
        G = hj.ContinuousTransferFunction(p[:2], jnp.concatenate([jnp.ones(1), p[2:]]))
        return jnp.mean(hj.simulate(hj.Hammerstein(F, G), V_GRAD, dt=0.1) ** 2)

    _check_grad(loss, [1.0, -10.0, 2.0, 1.0])


def test_grad_wrt_backlash_width():
    G = hj.ContinuousTransferFunction(jnp.array([1.0]), jnp.array([1.0, 1.4, 1.0]))
    v = 2.0 * jnp.sin(jnp.linspace(0.0, 12.0, 200))

    def loss(c):
        return jnp.mean(
            hj.simulate(hj.Hammerstein(hj.Backlash.from_width(c[0]), G), v, dt=0.1) ** 2
        )

    _check_grad(loss, [0.7])


@pytest.mark.slow  # diffrax compilation
def test_grad_through_diffrax_solve():
    t = jnp.linspace(0.0, 6.0, 61)
    u = jnp.sin(t)

    def loss(den):
        G = hj.ContinuousTransferFunction(
            jnp.array([1.0]), jnp.concatenate([jnp.ones(1), den])
        )
        return jnp.mean(hj.simulate_diffrax(G, t, u, interpolation="linear") ** 2)

    _check_grad(loss, [1.4, 1.0], rtol=1e-5)
