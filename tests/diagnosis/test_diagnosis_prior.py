"""The re-fit's prior at nominal (`--nominal-uncertainty`): the weight's formula,
and the fit lands on the maximum-a-posteriori point of that prior."""

import functools as ft

import jax.numpy as jnp
import jax.random as jr
import jax.tree_util as jtu
import numpy as np
import pytest

from hamjax.diagnosis.fit import fit_rows, nominal_mask, normal_equations
from hamjax.diagnosis.layout import (
    PRIOR_FLOOR,
    RELATIVE_STEP,
    prepare,
    prior_weight,
)
from hamjax.papers.gap.demo_cases import tiny_case


def test_prior_weight_is_noise_variance_over_prior_variance():
    # theta_j ~ N(0, (u / RELATIVE_STEP)^2) and noise std s: weight s^2 / var
    assert prior_weight(0.2, 0.05) == pytest.approx((0.05 * RELATIVE_STEP / 0.2) ** 2)
    assert prior_weight(None, 0.05) == PRIOR_FLOOR
    assert prior_weight(1e6, 1e-9) == PRIOR_FLOOR  # never below the tie-break
    for bad in (0.0, -0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="nominal uncertainty"):
            prior_weight(bad, 0.05)


@ft.cache  # one fit per uncertainty, shared by the tests
def _refit(uncertainty):
    case = tiny_case(jr.key(3), "parameter_mismatch", noise=0.01)
    prep = prepare(*case, nominal_uncertainty=uncertainty)
    rows = [r for name, r in prep.rows if name == "parameter_mismatch"]
    stacked = jtu.tree_map(lambda *x: jnp.stack(x), *rows)
    fit = fit_rows(stacked, prep.arrays, 200)
    return prep, rows[0], np.asarray(fit.theta[0])


@pytest.mark.parametrize("uncertainty", [0.02, 0.2])
def test_the_refit_is_the_map_point_of_the_stated_prior(uncertainty):
    prep, row, theta = _refit(uncertainty)
    w = float(prep.arrays.prior_weight)
    assert w > PRIOR_FLOOR
    _, _, g = normal_equations(jnp.asarray(theta), row, prep.arrays)
    mask = np.asarray(nominal_mask(row, prep.arrays))
    # the gradient of (record SSE + w |theta_nominal|^2) / 2 vanishes at the MAP
    # point; against the record gradient's size where the fit starts (theta0)
    _, _, g0 = normal_equations(row.theta0, row, prep.arrays)
    grad = np.asarray(g) + w * np.where(mask, theta, 0.0)
    assert np.linalg.norm(grad) < 1e-6 * np.linalg.norm(np.asarray(g0))


def test_a_firmer_prior_keeps_the_refit_closer_to_nominal():
    norms = [np.linalg.norm(_refit(u)[2]) for u in (0.02, 0.2, 0.5)]
    assert norms[0] < norms[1] < norms[2]
