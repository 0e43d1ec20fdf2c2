"""Sharding the realisation axis over 2 (forced host) devices gives the 1-device numbers."""

import textwrap

import jax
import jax.random as jr
import numpy as np
from helpers import run_on_two_devices

from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo


TRIAL = textwrap.dedent(
    """
    import jax.numpy as jnp
    import jax.random as jr

    def trial(key):
        x = jr.normal(key, (5,))
        return {"path": jnp.cumsum(x), "peak": jnp.max(x), "sign": jnp.sum(x > 0)}
    """
)

CHILD = TRIAL + textwrap.dedent(
    """
    import sys
    import jax
    import numpy as np
    jax.config.update("jax_enable_x64", True)
    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo, runner
    from hamjax.simulation.sharding import put_indices, realisation_sharding

    assert len(jax.devices()) == 2, jax.devices()
    sharding = realisation_sharding()
    chunk = runner._run_chunk(
        trial, jr.key(0), put_indices(np.arange(4, dtype=np.uint32), sharding), sharding
    )
    # chunk 3 is rounded up to 4 = 2 devices x 2; R = 13 leaves a padded last chunk.
    res = run_monte_carlo(jr.key(11), trial, MonteCarloConfig(realisations=13, chunk=3))
    np.savez(
        sys.argv[1], devices=len(chunk["path"].sharding.device_set), **res
    )
    """
)


def test_two_devices_give_the_single_device_numbers(tmp_path):
    sharded = run_on_two_devices(CHILD, tmp_path, timeout=300)
    assert int(sharded["devices"]) == 2  # the chunk really was split over both

    namespace: dict = {}
    exec(TRIAL, namespace)
    assert len(jax.devices()) == 1
    single = run_monte_carlo(
        jr.key(11), namespace["trial"], MonteCarloConfig(realisations=13, chunk=5)
    )
    # Fixed key 11 in both processes: the same draws for every run; each device runs
    # the same per-realisation program, so only a reduction order may differ.
    for name in ("path", "peak"):
        np.testing.assert_allclose(sharded[name], single[name], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(sharded["sign"], single["sign"])
