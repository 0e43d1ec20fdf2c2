"""The batched candidate fit: split over devices, and the finishing stage
(`_continue_stopped`) that restarts the re-fit from a structural row's nominal part."""

import textwrap

import jax
import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
import pytest
from helpers import run_on_two_devices

from hamjax.diagnosis.diagnose import REFIT, _continue_stopped
from hamjax.diagnosis.fit import fit_cases
from hamjax.diagnosis.layout import prepare
from hamjax.internal.gap_cases import tiny_case


SETUP = textwrap.dedent(
    """
    import jax.numpy as jnp
    import jax.random as jr
    import jax.tree_util as jtu
    from hamjax.diagnosis.layout import prepare
    from hamjax.internal.gap_cases import tiny_case

    def stack(xs):
        return jtu.tree_map(lambda *x: jnp.stack(x), *xs)

    def grid(keys_effects):
        preps = [
            prepare(*tiny_case(jr.key(k), e, noise=1e-3), length=512, n_params=13)
            for k, e in keys_effects
        ]
        rows = stack([stack([r for _, r in p.rows]) for p in preps])
        return rows, stack([p.arrays for p in preps])
    """
)

CHILD = SETUP + textwrap.dedent(
    """
    import sys
    import jax
    import numpy as np
    import hamjax as hj
    from hamjax.diagnosis.fit import fit_cases

    hj.enable_x64()
    two = fit_cases(*grid([(3, "extra_pole"), (4, "saturation")]), 6)  # split cases
    one = fit_cases(*grid([(5, "backlash")]), 6)  # one case: split its rows
    np.savez(
        sys.argv[1], devices=jax.device_count(), two_sse=two.sse_est,
        one_sse=one.sse_est,
    )
    """
)


@pytest.mark.slow
def test_two_devices_give_the_single_device_fit(tmp_path):
    # Each row is an independent fit: splitting cases (or one case's rows) over two
    # devices changes only the vector width XLA computes with, i.e. rounding. The
    # damped Gauss-Newton steps amplify rounding along ill-conditioned directions
    # (measured: 3e-7 relative in the SSE after 6 steps), hence 1e-5; a row fitted
    # on the wrong case or with another row's start differs by O(1).
    sharded = run_on_two_devices(CHILD, tmp_path)
    assert int(sharded["devices"]) == 2
    ns: dict = {}
    exec(SETUP, ns)
    assert jax.device_count() == 1
    two = fit_cases(*ns["grid"]([(3, "extra_pole"), (4, "saturation")]), 6)
    one = fit_cases(*ns["grid"]([(5, "backlash")]), 6)
    for name, ref in (("two", two), ("one", one)):
        np.testing.assert_allclose(sharded[f"{name}_sse"], ref.sse_est, rtol=1e-5)


def _stack(xs):
    return jtu.tree_map(lambda *x: jnp.stack(x), *xs)


@pytest.mark.slow
def test_refit_restarted_from_structural_row_leaves_a_local_minimum():
    # A `none` case: the re-fit's optimum is the best any row reaches. Plant a fake
    # local minimum in the re-fit row (far parameters, high SSE, marked converged):
    # the finishing stage must restart it from the best structural row's nominal
    # parameters and land on the optimum of an uninterrupted fit.
    plant, dt, est, val = tiny_case(jr.key(8), "none", noise=1e-3)
    prep = prepare(plant, dt, est, val)
    rows = _stack([_stack([r for _, r in prep.rows])])
    cases = _stack([prep.arrays])
    full = jax.device_get(fit_cases(rows, cases, 200))
    i_pm = [name for name, _ in prep.rows].index(REFIT)
    bad = jtu.tree_map(np.array, full)
    bad.theta[0, i_pm] = bad.theta[0, i_pm] + 5.0
    bad.sse_est[0, i_pm] = 1e3 * full.sse_est[0, i_pm]
    bad.result[0, i_pm] = 0
    done = _continue_stopped([prep], rows, cases, bad)
    np.testing.assert_allclose(done.sse_est[0, i_pm], full.sse_est[0, i_pm], rtol=1e-6)
    # rows that had converged and are not the re-fit are left untouched
    others = [k for k in range(len(prep.rows)) if k != i_pm and full.result[0, k] == 0]
    np.testing.assert_array_equal(done.sse_est[0, others], full.sse_est[0, others])


def test_numpy_nominal_response_matches_scipy():
    import scipy.signal

    from hamjax.diagnosis.layout import _companion_numpy, _lfilter_numpy

    rng = np.random.default_rng(1)
    u = rng.normal(size=500)
    b, a = np.array([0.0, 0.06, 0.01, 0.0]), np.array([1.0, -2.02, 1.349, -0.297])
    np.testing.assert_allclose(
        _lfilter_numpy(b, a, u), scipy.signal.lfilter(b, a, u), rtol=0, atol=1e-12
    )
    for num, den in (([2.0, 1.0], [1.0, 3.0, 2.0]), ([1.0, 2.0, 1.0], [2.0, 3.0, 2.0])):
        for mine, ref in zip(
            _companion_numpy(np.array(num), np.array(den)),
            scipy.signal.tf2ss(num, den),
            strict=True,
        ):
            np.testing.assert_allclose(mine, ref, atol=1e-14)
