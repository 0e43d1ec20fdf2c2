"""Monte Carlo draws: the Box-Muller normal, blocks folded per realisation, the key
implementation in the manifest; the drawn time-major summaries equal the reference."""

import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.stats
from helpers import run_on_two_devices

import hamjax as hj
from hamjax.montecarlo import MonteCarloConfig, random as mcrandom, run_monte_carlo
from hamjax.papers.engine.studies.simulation_throughput import make_trial
from hamjax.papers.seed001.studies._normalised_gradient_trial import (
    make_gradient_trial,
)
from hamjax.simulation.time_major import output_summary


def test_sincos_and_normal_distribution():
    t = np.linspace(0.0, 1.0, 100_001, endpoint=False)
    sin, cos = jax.jit(mcrandom._sincos_2pi)(jnp.asarray(t))
    np.testing.assert_allclose(sin, np.sin(2 * np.pi * t), rtol=0, atol=2e-15)
    np.testing.assert_allclose(cos, np.cos(2 * np.pi * t), rtol=0, atol=2e-15)
    z = np.asarray(jax.jit(lambda k: mcrandom.normal(k, (400_001,)))(jr.key(0)))
    assert z.shape == (400_001,) and z.dtype == np.float64
    assert abs(z.mean()) < 5 / np.sqrt(z.size)
    assert abs(z.std() - 1.0) < 5 / np.sqrt(2 * z.size)
    assert scipy.stats.kstest(z, "norm").pvalue > 1e-3
    assert abs(scipy.stats.kurtosis(z)) < 0.05
    # Pairs (cos, sin) of one radius are uncorrelated.
    half = z.size // 2
    assert abs(np.corrcoef(z[:half], z[half : 2 * half])[0, 1]) < 5 / np.sqrt(half)


@pytest.mark.parametrize("impl", ["threefry2x32", "threefry4x32"])
def test_blocks_time_major_equal_blocks(impl):
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(4, impl=impl), r))(jnp.arange(3))
    n = 2 * mcrandom.BLOCK + 7
    ref = jax.vmap(lambda k: mcrandom.normal_blocks(k, n))(keys)
    got = jnp.concatenate(
        [mcrandom.normal_block_time_major(keys, b) for b in range(3)], axis=0
    )[:n]
    np.testing.assert_array_equal(got.T, ref)


@pytest.mark.parametrize("n_samples", [30, 50, 137, 300])
def test_drawn_summaries_equal_simulate(n_samples):
    """The engine's form (drawn inside the scan) equals vmap of the trial and the
    summaries of `hamjax.simulate` on the same inputs, for any length."""
    trial = make_trial(n_samples=n_samples, width=0.4, unroll=2)
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(5), r))(jnp.arange(4))
    batched = eqx.filter_jit(trial.batched)(keys)
    for r, k in enumerate(keys):
        v = trial._inputs(k)
        w = np.asarray(hj.simulate(trial.plant, v))
        ref = output_summary(trial.plant, v)
        np.testing.assert_allclose(ref["rms"], np.sqrt(np.mean(w**2)), rtol=1e-12)
        for name in ("mean", "rms", "max_abs"):
            np.testing.assert_allclose(batched[name][r], ref[name], rtol=1e-12)


@pytest.mark.parametrize("impl", ["threefry2x32", "threefry4x32"])
def test_engine_draws_depend_only_on_seed_and_index(impl):
    trial = make_trial(n_samples=120)
    key = jr.key(9, impl=impl)
    runs = [
        run_monte_carlo(key, trial, MonteCarloConfig(realisations=7, chunk=c))
        for c in (1, 3, 8)
    ]
    ref = [trial(jr.fold_in(key, r)) for r in range(7)]
    for res in runs:
        for name in ("mean", "rms", "max_abs"):
            np.testing.assert_allclose(
                res[name], [x[name] for x in ref], rtol=1e-12, atol=0
            )


# (4.1) is a contraction-like recursion over up to 300 steps whose time-major form
# sums phi^T theta in another order (10 terms): rounding differences of a few ulp
# per step, as in the time-major test of tests/montecarlo/test_montecarlo.py, so the
# same rtol 1e-10 / atol 1e-12 (estimates are O(1)).
GRADIENT_TOL = dict(rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("n_samples", [30, 50, 137])
def test_drawn_gradient_equals_the_trial(n_samples):
    """Workload 2's engine form (noise drawn inside the scan) equals vmap of the
    per-realisation trial, (4.1) on regressor(v, w + e_r), for any length."""
    trial, _ = make_gradient_trial(n_samples=n_samples, unroll=3)
    keys = jax.vmap(lambda r: jr.fold_in(jr.key(6), r))(jnp.arange(4))
    batched = eqx.filter_jit(trial.batched)(keys)
    assert batched.shape == (4, 10)
    # Less than a block, one block, blocks and a partial block.
    ref = eqx.filter_jit(eqx.filter_vmap(trial))(keys)
    np.testing.assert_allclose(batched, ref, **GRADIENT_TOL)


def test_gradient_engine_depends_only_on_seed_and_index():
    trial, _ = make_gradient_trial(n_samples=120)
    key = jr.key(9, impl="threefry4x32")
    runs = [
        run_monte_carlo(key, trial, MonteCarloConfig(realisations=7, chunk=c))
        for c in (3, 8)  # a padded last chunk; one chunk wider than R
    ]
    keys = jax.vmap(lambda r: jr.fold_in(key, r))(jnp.arange(7))
    ref = eqx.filter_jit(eqx.filter_vmap(trial))(keys)
    for res in runs:
        # The same draws whatever the chunk; only the vector width (and with it
        # the compiler's use of FMA in remainder loops) changes: rounding only.
        np.testing.assert_allclose(res, ref, **GRADIENT_TOL)


CHILD = textwrap.dedent(
    """
    import sys
    import jax
    import jax.random as jr
    import numpy as np
    jax.config.update("jax_enable_x64", True)
    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo
    from hamjax.papers.engine.studies.simulation_throughput import make_trial
    from hamjax.papers.seed001.studies._normalised_gradient_trial import (
        make_gradient_trial,
    )

    assert len(jax.devices()) == 2, jax.devices()
    trial = make_trial(n_samples=120)
    res = {}
    for impl in ("threefry2x32", "threefry4x32"):
        got = run_monte_carlo(
            jr.key(9, impl=impl), trial, MonteCarloConfig(realisations=7, chunk=3)
        )
        res[impl] = got["rms"]
    gradient, _ = make_gradient_trial(n_samples=120)
    res["gradient"] = run_monte_carlo(
        jr.key(9), gradient, MonteCarloConfig(realisations=7, chunk=3)
    )
    np.savez(sys.argv[1], **res)
    """
)


@pytest.mark.slow
def test_two_devices_give_the_one_device_draws(tmp_path):
    sharded = run_on_two_devices(CHILD, tmp_path, timeout=300)
    trial = make_trial(n_samples=120)
    for impl in ("threefry2x32", "threefry4x32"):
        single = run_monte_carlo(
            jr.key(9, impl=impl), trial, MonteCarloConfig(realisations=7, chunk=5)
        )
        np.testing.assert_allclose(sharded[impl], single["rms"], rtol=1e-12, atol=0)
    gradient, _ = make_gradient_trial(n_samples=120)
    single = run_monte_carlo(
        jr.key(9), gradient, MonteCarloConfig(realisations=7, chunk=5)
    )
    np.testing.assert_allclose(sharded["gradient"], single, rtol=1e-12, atol=0)


def test_manifest_records_key_impl_and_refuses_another(tmp_path):
    trial = make_trial(n_samples=60)
    config = MonteCarloConfig(realisations=4, chunk=2)
    run_monte_carlo(
        jr.key(1, impl="threefry4x32"), trial, config, out=tmp_path, quiet=True
    )
    import json

    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["key_impl"] == "threefry4x32" and manifest["processes"] == 1
    again = run_monte_carlo(
        jr.key(1, impl="threefry4x32"), trial, config, out=tmp_path, quiet=True
    )
    assert again["rms"].shape == (4,)
    with pytest.raises(ValueError, match="key_impl"):
        run_monte_carlo(jr.key(1), trial, config, out=tmp_path, quiet=True)
