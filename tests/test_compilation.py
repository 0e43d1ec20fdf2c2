"""Guards against re-compiling (the BlackJAX `test_compilation.py` idea): a jitted
simulation called again with new data or new plant parameters of the same shapes
must reuse its compilation."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import hamjax as hj


def _plants():
    grid = jnp.linspace(-2.0, 2.0, 9)
    return [
        hj.Hammerstein(
            hj.PiecewiseLinear(k1=1.0, k2=2.0, d1=1.0, d2=-2.0, l1=1.0, l2=-2.0),
            hj.DiscreteTransferFunction(
                jnp.array([0.0, 1.0, -2.0]), jnp.array([1.0, -1.5, 0.56])
            ),
        ),
        hj.Hammerstein(
            hj.Backlash.from_table(grid, grid - 0.2, grid + 0.2),
            hj.ContinuousTransferFunction(
                jnp.array([1.0, -10.0]), jnp.array([1.0, 2.0, 1.0])
            ),
        ),
    ]


@pytest.mark.parametrize(
    "plant", _plants(), ids=["seed001-discrete", "backlash-continuous"]
)
def test_simulate_compiles_once_for_new_data(plant):
    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def run(plant, v):
        return hj.simulate(plant, v, dt=0.1)

    _, v1 = hj.random_staircase(jr.key(0), n_samples=64, hold=4, low=-3.0, high=3.0)
    _, v2 = hj.random_staircase(jr.key(1), n_samples=64, hold=4, low=-3.0, high=3.0)
    w1, w2 = run(plant, v1), run(plant, v2)
    # New parameter values (same structure and shapes) must not re-trace either.
    gain = lambda p: p.linear.b if hasattr(p.linear, "b") else p.linear.num
    doubled = eqx.tree_at(gain, plant, 2.0 * gain(plant))
    w3 = run(doubled, v1)
    assert not np.allclose(w1, w2)
    # fixed keys 0 and 1; doubling the numerator is exact, the rest is reordering
    np.testing.assert_allclose(w3, 2.0 * w1, rtol=1e-12, atol=1e-12)


def test_noisy_trial_batch_compiles_once():
    # A per-realisation trial (simulate + noise, key first) batched by vmap over
    # fold_in keys, run twice with different root keys.
    plant = _plants()[0]
    _, v = hj.pe_impulse_sequence(jnp.array([-6.0, -3.0, 3.0, 6.0]), order=2, periods=5)

    @eqx.debug.assert_max_traces(max_traces=1)
    def trial(key, v):
        w = hj.simulate(plant, v)
        return hj.add_noise(key, w, hj.WhiteNoise(0.1))

    @eqx.filter_jit
    def batch(root, v):
        keys = jax.vmap(lambda r: jr.fold_in(root, r))(jnp.arange(8))
        return jax.vmap(trial, in_axes=(0, None))(keys, v)

    y1 = batch(jr.key(0), v)
    y2 = batch(jr.key(1), v)
    assert y1.shape == y2.shape == (8, v.shape[0])
    assert not np.allclose(y1, y2)
    # Realisation r does not depend on the batch: it equals the unbatched trial
    # (fixed key 0: the same draws every run).
    np.testing.assert_allclose(
        y1[3],
        hj.add_noise(
            jr.fold_in(jr.key(0), 3), hj.simulate(plant, v), hj.WhiteNoise(0.1)
        ),
        rtol=1e-12,
        atol=1e-12,
    )


def test_retrace_guard_detects_a_new_shape():
    # The guard itself works: a new input length is a new trace and must raise.
    plant = _plants()[0]

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def run(v):
        return hj.simulate(plant, v)

    run(jnp.ones(10))
    with pytest.raises(RuntimeError, match="can only be traced 1 times"):
        run(jnp.ones(11))
