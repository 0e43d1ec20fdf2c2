"""`hamjax.simulate_batch` (time-major) equals vmap of `hamjax.simulate`; the
batched (4.1) equals the per-record reference."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hamjax as hj
from hamjax.identification import seed001 as rpl
from hamjax.simulation import time_major


DTF = hj.DiscreteTransferFunction([0.0, 1.0, -2.0], [1.0, -1.5, 0.56])
PLANTS = {
    "backlash": hj.Hammerstein(hj.Backlash.from_width(0.5), DTF),
    "dead-zone": hj.Hammerstein(
        hj.DeadZone.symmetric(0.3), hj.DiscreteTransferFunction([0.5, 0.2], [1, -0.7])
    ),
    "saturation-static-gain": hj.Hammerstein(
        hj.Saturation(lower=-0.8, upper=1.1), hj.DiscreteTransferFunction([2.0], [1.0])
    ),
    "piecewise-linear": hj.Hammerstein(
        hj.PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0), DTF
    ),
    "state-space": hj.Hammerstein(
        hj.Backlash.from_width(0.2),
        hj.DiscreteStateSpace(
            [[0.5, 0.1], [-0.2, 0.7]], [[1.0], [0.5]], [[1.0, -1.0]], [[0.3]]
        ),
    ),
}


def _inputs(batch=5, time=157, seed=0):  # 157: not a multiple of the block
    return jnp.asarray(np.random.default_rng(seed).normal(size=(batch, time)))


@pytest.mark.parametrize("name", list(PLANTS))
def test_simulate_batch_equals_vmap_of_simulate(name):
    plant, V = PLANTS[name], _inputs()
    ref = jax.vmap(lambda v: hj.simulate(plant, v))(V)
    got = hj.simulate_batch(plant, V, unroll=3)
    assert got.shape == V.shape
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    tm = jax.jit(lambda V: hj.simulate_batch(plant, V, time_axis=0))(V.T)
    np.testing.assert_allclose(tm.T, ref, rtol=1e-12, atol=1e-12)


def _general(plant):
    """The time-major step of `plant` through `Backlash.step` (the play form off)."""
    return time_major._Stepper(plant, time_major.stepper(plant).linear, play=False)


@pytest.mark.parametrize("width", [0.0, 0.37, 0.5, 2.0])
def test_play_operator_step_equals_backlash_step_bit_for_bit(width):
    """A straight-line backlash is stepped as the play operator; it equals the
    general `Backlash.step` exactly, also on inputs that stop, reverse and
    repeat (a staircase with steps smaller and larger than the width)."""
    plant = hj.Hammerstein(hj.Backlash.from_width(width), DTF)
    rng = np.random.default_rng(3)
    noise = rng.normal(size=(6, 400))
    stairs = np.repeat(rng.normal(scale=0.6, size=(6, 80)), 5, axis=1)
    V = jnp.asarray(np.concatenate([noise, stairs]))
    play = time_major.stepper(plant)
    assert play.play

    def run(st):
        _, w = jax.lax.scan(lambda c, vk: st.step(c, vk), st.init(V[:, 0]), V.T)
        return w

    np.testing.assert_array_equal(run(play), run(_general(plant)))
    ref = jax.vmap(lambda v: hj.simulate(plant, v))(V)
    np.testing.assert_array_equal(hj.simulate_batch(plant, V).T, ref.T)


def test_play_operator_only_where_it_is_exact():
    """Crossed borders, a given start, tabulated borders and traced offsets take
    the general step."""
    assert time_major.is_play_operator(hj.Backlash.from_width(0.5))
    crossed = hj.Backlash(
        ascending=hj.Shifted(offset=0.3), descending=hj.Shifted(offset=-0.3)
    )
    assert not time_major.is_play_operator(crossed)
    assert not time_major.is_play_operator(hj.Backlash.from_width(0.5, u0=0.1))
    grid = jnp.linspace(-3.0, 3.0, 7)
    table = hj.Backlash.from_table(grid, grid - 0.2, grid + 0.2)
    assert not time_major.is_play_operator(table)
    assert not time_major.is_play_operator(hj.DeadZone.symmetric(0.3))
    seen = []

    @jax.jit
    def traced(c):
        seen.append(time_major.is_play_operator(hj.Backlash.from_width(c)))
        return c

    traced(0.5)
    assert seen == [False]


def test_simulate_batch_continuous_by_zoh():
    plant = hj.Hammerstein(
        hj.Backlash.from_width(0.3),
        hj.ContinuousTransferFunction([1.0], [1.0, 3.0, 2.0]),
    )
    V = _inputs(time=80)
    ref = jax.vmap(lambda v: hj.simulate(plant, v, dt=0.1))(V)
    got = hj.simulate_batch(plant, V, dt=0.1)
    np.testing.assert_allclose(got, ref, rtol=1e-11, atol=1e-12)
    with pytest.raises(ValueError, match="dt"):
        hj.simulate_batch(plant, V)


def test_simulate_batch_checks_its_input():
    plant = PLANTS["backlash"]
    with pytest.raises(ValueError, match="2-D"):
        hj.simulate_batch(plant, jnp.zeros(5))
    with pytest.raises(ValueError, match="NaN|finite"):
        hj.simulate_batch(plant, jnp.full((2, 4), jnp.nan))
    unstable = hj.Hammerstein(
        hj.Identity(), hj.DiscreteTransferFunction([1.0], [1.0, -1.2])
    )
    with pytest.raises(ValueError, match="unstable"):
        hj.simulate_batch(unstable, _inputs())
    assert hj.simulate_batch(unstable, _inputs(), allow_unstable=True).shape == (5, 157)
    with pytest.raises(ValueError, match="time_axis"):
        hj.simulate_batch(plant, _inputs(), time_axis=2)


def test_normalised_gradient_batch_equals_reference():
    levels = jnp.array([-6.0, -3.0, 3.0, 6.0])
    _, v = hj.pe_impulse_sequence(levels, order=2, periods=6)
    plant = PLANTS["piecewise-linear"]
    w = hj.simulate(plant, v)
    Y = w[None] + 0.1 * _inputs(batch=3, time=v.shape[0], seed=1)
    theta0 = jnp.zeros(10)
    got = rpl.normalised_gradient_batch(
        v, Y, levels=levels, order=2, theta0=theta0, rho=12.0
    )

    @jax.jit
    def reference(y):
        phi = rpl.regressor(v, y, levels=levels, order=2)
        return rpl.normalised_gradient(phi, y, theta0=theta0, rho=12.0)[0]

    for r in range(3):
        np.testing.assert_allclose(got[r], reference(Y[r]), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("time", [1, 30, 50, 101])
def test_simulate_batch_any_length(time):
    plant, V = PLANTS["backlash"], _inputs(batch=3, time=time)
    ref = jax.vmap(lambda v: hj.simulate(plant, v))(V)
    np.testing.assert_allclose(hj.simulate_batch(plant, V), ref, rtol=1e-12, atol=1e-12)
